"""The numba types the compiled parts meet at: a scene's generated right-hand side and guards are compiled
with these exact signatures, and the integrators take them as first-class functions, so one compiled
integrator serves every scene and its on-disk cache stays valid (a function passed by its own type
would make numba compile, and cache, the integrator anew for every scene)."""

from numba import types

RHS_SIGNATURE = types.void(types.float64, types.float64[::1], types.float64[::1], types.float64[::1])
"""rhs(t [s], y, p, dydt): writes dy/dt for state y at time t into dydt; p: the scene's parameters and the
segment's inputs (load piece, throttle, mode codes, switch window), laid out by the code generator."""

GUARDS_SIGNATURE = types.void(types.float64, types.float64[::1], types.float64[::1], types.float64[::1])
"""guards(t [s], y, p, levels): writes the level of every guard into levels (>= 0 while its mode holds;
+inf for a guard the mode in p does not have)."""

REACTIONS_SIGNATURE = types.void(types.float64, types.float64[::1], types.float64[::1], types.float64[::1])
"""reactions(t [s], y, p, squares): writes |R_j|^2 [N^2] of each journal with friction into squares (joint friction's
reactions R0_j + R1_j epsilon at the rhs's epsilon; integrators' step limit near their branch points)."""

RHS_TYPE = types.FunctionType(RHS_SIGNATURE)
GUARDS_TYPE = types.FunctionType(GUARDS_SIGNATURE)
REACTIONS_TYPE = types.FunctionType(REACTIONS_SIGNATURE)
