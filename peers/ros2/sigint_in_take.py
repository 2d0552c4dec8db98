"""Run an rclpy program's ``main()`` (as ``ros2 run`` does) and deliver SIGINT to it at the
worst moment for rclpy: while ``take_message`` runs Python code.

    sigint_in_take.py PROGRAM.py [ARGS...]

rclpy's ``take_message`` (``rclpy/src/rclpy/subscription.cpp``) builds the message object
of a subscription that is not ``raw`` by calling the message classes' Python code; a
``KeyboardInterrupt`` raised there becomes a ``RuntimeError`` ("Unable to convert call
argument '0' to Python object") out of ``rclpy.spin``, which a program's ``except
KeyboardInterrupt`` does not catch. A real Ctrl-C lands there by chance (the more
messages, the likelier); this runner makes it certain: a profile hook on the main thread
sends the process SIGINT (``os.kill``) at the first Python call made inside a
``take_message`` call, and prints ``SIGINT INSIDE take_message`` on stderr first. A
program that never runs Python code inside a take is never signalled by the hook (the
test sends its own SIGINT). Run by ``tests/compat/test_compat_programs_rclpy.py`` under the
ROS 2 venv's python, never imported.
"""

import os
import runpy
import signal
import sys

_inside = [False]


def _profile(frame, event, arg):
    if event == "c_call" and getattr(arg, "__name__", "") == "take_message":
        _inside[0] = True
    elif event in ("c_return", "c_exception") and getattr(arg, "__name__", "") == "take_message":
        _inside[0] = False
    elif event == "call" and _inside[0]:
        sys.setprofile(None)  # once
        print("SIGINT INSIDE take_message", file=sys.stderr, flush=True)
        os.kill(os.getpid(), signal.SIGINT)


def main():
    sys.argv = sys.argv[1:]
    program = runpy.run_path(sys.argv[0])
    sys.setprofile(_profile)  # the main thread: where rclpy.spin takes messages
    program["main"]()


if __name__ == "__main__":
    main()
