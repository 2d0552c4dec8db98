from collections.abc import Hashable

import numpy as np
import numpy.typing as npt

class Projector:
    @property
    def key(self) -> Hashable | None: ...
    def set_table(
        self, key: Hashable, cos: npt.NDArray[np.float64], sin: npt.NDArray[np.float64]
    ) -> None: ...
    def project(
        self,
        ranges: npt.NDArray[np.float32],
        intensities: npt.NDArray[np.float32],
        opts: int,
        range_cutoff: float,
        range_min: float,
        time_increment: float,
    ) -> tuple[bytes, int]: ...
