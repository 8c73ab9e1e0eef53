"""Governors: what sets the throttle of a governed machine. Each kind is one module with one class deriving from the
governor level's interface (governors/kind.py, GovernorKind) and a builder registered for its scene class: the
centrifugal governor, direct or indirect, with Porter's or Hartnell's sensor (governors/mechanical.py) and the
electronic PI governor (governors/pi.py). build_governor assembles a scene's."""

from __future__ import annotations

from collections.abc import Callable

from mech_regulator.governors import mechanical, pi
from mech_regulator.governors.kind import GovernorKind, Guard, MachineMode, Mode, builder_of, check_covered
from mech_regulator.scene import governor_keys

check_covered(governor_keys.Governor)


def build_governor(spec: governor_keys.Governor, balance_throttle: Callable[[float], float]) -> GovernorKind:
    """Assemble a scene's governor with the builder its kind registered (governors.kind.builds). balance_throttle(omega)
    is the throttle at which the cycle-averaged drive balances the initial load at crank speed omega [rad/s]."""
    return builder_of(spec)(spec, balance_throttle)


__all__ = ["GovernorKind", "Guard", "MachineMode", "Mode", "build_governor", "mechanical", "pi"]
