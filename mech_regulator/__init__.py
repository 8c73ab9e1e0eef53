"""mech_regulator: real motion of machines and the regulation of their speed (theory of machines).

The physics core (scene, model, mechanisms, effects, solvers, analysis) imports neither rclpy nor
rerun; the command line and, later, the ROS nodes and viewers are thin layers over it.

Importing the package first fixes the kernels of OpenBLAS, the BLAS numpy and scipy load, on an x86-64 CPU with AVX2
and FMA: OpenBLAS picks its kernels by the CPU it loads on, and on a CPU with AVX-512 its matrix-vector kernels round
differently from the AVX2 ones, so the same run ended 1 to 4 units in the last place apart on two machines of the same
kind (scipy's Runge-Kutta steps sum their stages with a BLAS product: the reference path), and a long conservative
run's energy drift by 5e-6 of itself. With the Haswell kernels (AVX2, FMA) on every such machine the numbers are the
same on all of them (docs/speed.md, "The same numbers on every machine"). A value of OPENBLAS_CORETYPE set before is
kept; a process that loaded numpy before this package keeps the kernels it loaded.
"""

import os
import platform

__version__ = "0.1.0"


def _cpu_flags() -> set[str]:
    """The CPU's feature flags (Linux's /proc/cpuinfo); empty where they cannot be read."""
    try:
        with open("/proc/cpuinfo") as cpuinfo:
            for line in cpuinfo:
                if line.startswith("flags"):
                    return set(line.split(":", 1)[1].split())
    except OSError:
        pass
    return set()


if platform.machine().lower() in ("x86_64", "amd64") and {"avx2", "fma"} <= _cpu_flags():
    os.environ.setdefault("OPENBLAS_CORETYPE", "Haswell")
