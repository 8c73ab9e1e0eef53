"""Processes seen from Linux: whether one still runs, and a child that ends with its parent. The launcher's nodes,
the command server and the benchmarks all start or watch processes."""

from __future__ import annotations

import os
import signal


def process_alive(pid: int) -> bool:
    """Whether the process runs (a zombie waiting for its parent's reaping counts as ended)."""
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False
    except OSError:  # no /proc: ask the kernel
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        except PermissionError:  # another user's
            return True
        return True


def die_with_parent() -> None:
    """In a child process before it starts (Linux): receive SIGINT when its parent dies, however it dies (even
    SIGKILL), so that the child (a node; `bench soak`'s run) closes what it has and ends, and none is left behind."""
    import ctypes

    PR_SET_PDEATHSIG = 1
    ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGINT)
