"""The compiled fast path: the right-hand side a scene assembles (only its effects) generated as source,
compiled once by numba and cached on disk, stepped by compiled integrators (solvers/compiled/integrators.py).
The pure-Python path (solvers/time_domain.py) stays the reference it is tested against."""
