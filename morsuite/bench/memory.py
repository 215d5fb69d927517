"""Peak memory of a piece of code: tracemalloc peak and peak resident set size.

:class:`MemoryProbe` records, around the code it wraps,

* ``traced_peak_mb``: Python/NumPy allocations (tracemalloc). SuperLU's factor
  storage is malloc'd in C and invisible to it;
* ``rss_delta_mb``: the peak resident set size during the code minus the RSS just
  before it. The kernel's high-water mark is reset through ``/proc/self/clear_refs``
  where Linux allows it; otherwise the lifetime peak is used (``rss_peak_reset``
  False), which can only overstate the delta.
"""

from __future__ import annotations

import gc
import os
import tracemalloc

__all__ = ["MemoryProbe", "MIB"]

MIB = 2.0 ** 20


def _rss_bytes() -> int | None:
    try:
        import psutil

        return int(psutil.Process().memory_info().rss)
    except ImportError:
        try:
            with open("/proc/self/statm") as fh:
                return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
        except (OSError, ValueError):
            return None


def _hwm_bytes() -> int | None:
    """The kernel's peak RSS of this process (VmHWM), or ru_maxrss."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        import resource

        return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) * 1024
    except ImportError:  # pragma: no cover - not on Linux
        return None


def _reset_hwm() -> bool:
    """Reset the peak-RSS counter (Linux >= 4.0: write 5 to /proc/self/clear_refs)."""
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
        return True
    except OSError:
        return False


class MemoryProbe:
    """Context manager: tracemalloc peak and peak-RSS delta of the code it wraps.

    Attributes after exit: ``traced_peak_mb``, ``rss_before_mb``,
    ``rss_peak_mb``, ``rss_delta_mb``, ``hwm_reset`` (False: the peak is the
    process's lifetime peak, so the delta is an upper bound).
    """

    def __init__(self, trace: bool = True):
        self.trace = trace

    def __enter__(self):
        gc.collect()
        self.hwm_reset = _reset_hwm()
        rss = _rss_bytes()
        self.rss_before_mb = rss / MIB if rss is not None else float("nan")
        if self.trace:
            tracemalloc.start()
        return self

    def __exit__(self, *exc):
        if self.trace:
            self.traced_peak_mb = tracemalloc.get_traced_memory()[1] / MIB
            tracemalloc.stop()
        else:
            self.traced_peak_mb = float("nan")
        hwm = _hwm_bytes()
        self.rss_peak_mb = hwm / MIB if hwm is not None else float("nan")
        self.rss_delta_mb = max(self.rss_peak_mb - self.rss_before_mb, 0.0)
        return False

    def as_dict(self) -> dict:
        """The measured peaks and deltas in MB, as plain data."""
        return {"tracemalloc_peak_mb": self.traced_peak_mb, "rss_before_mb": self.rss_before_mb,
                "rss_peak_mb": self.rss_peak_mb, "rss_delta_mb": self.rss_delta_mb,
                "rss_peak_reset": self.hwm_reset}
