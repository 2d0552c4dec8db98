"""The DDS domain ids the tests take (``tests/dds_domains.py``): pytest-xdist's workers get
disjoint shares that together hold every id, and no id is handed out twice in a process."""

from __future__ import annotations

import dds_domains
import pytest
from dds_domains import DOMAIN_IDS, new_domain, worker_share


def test_outside_xdist_a_run_takes_every_id(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("PYTEST_XDIST_WORKER", raising=False)
    monkeypatch.delenv("PYTEST_XDIST_WORKER_COUNT", raising=False)
    assert worker_share() == list(range(1, 233))


@pytest.mark.parametrize("count", [1, 2, 3, 8])
def test_workers_take_disjoint_shares_of_every_id(
    count: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("PYTEST_XDIST_WORKER_COUNT", str(count))
    shares = []
    for n in range(count):
        monkeypatch.setenv("PYTEST_XDIST_WORKER", f"gw{n}")
        shares.append(set(worker_share()))
    assert set().union(*shares) == set(DOMAIN_IDS)
    assert sum(len(s) for s in shares) == len(DOMAIN_IDS)  # no id in two shares
    assert min(len(s) for s in shares) >= len(DOMAIN_IDS) // count


def test_a_process_never_gets_an_id_twice_then_says_it_ran_out(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setenv("PYTEST_XDIST_WORKER_COUNT", "2")
    monkeypatch.setenv("PYTEST_XDIST_WORKER", "gw1")
    monkeypatch.setattr(dds_domains, "_used", set())
    got = [new_domain() for _ in range(116)]
    assert sorted(got) == list(range(1, 233, 2))  # gw1 of 2: the odd ids, each once
    with pytest.raises(RuntimeError, match="no free ROS 2 domain id left"):
        new_domain()
