"""Governors: a centrifugal sensor that sets the throttle, directly or through a servo-motor.

The governed machine's state is y = [phi, omega, a, a', (s, (zeta))]: crank angle and speed, the arm
angle of the sensor and its rate, for indirect action the servo position s (= throttle) and, with
isodromic feedback, the dashpot's pilot shift zeta [m]. The drive is scaled, M_d = throttle(y) M_drive.

Dry friction and hard stops make the governor a hybrid system. Its discrete mode is a pair
(sleeve mode, servo mode):
- sleeve: 'free' (no Coulomb friction at all), 'up' / 'down' (sliding, kinetic friction of a fixed
  sign), 'stuck' (held by static friction), 'low' / 'high' (resting on a hard stop);
- servo: 'free', 'low' / 'high' (on a travel stop), '' for a direct governor.
In each mode the right-hand side is smooth. A mode holds while all its guards are >= 0; the solver
locates the first guard that turns negative and applies its transition, so a stuck sleeve does not
creep, a sleeve on a stop stays there until the forces pull it off, and stops are inelastic.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TypedDict

import numpy as np

from mech_regulator.governors import servo as servo_motor
from mech_regulator.governors.centrifugal import PorterSensor
from mech_regulator.governors.hartnell import HartnellSensor
from mech_regulator.governors.pi import ElectronicGovernor
from mech_regulator.governors.sensor import CentrifugalSensor
from mech_regulator.governors.valve import ValveCharacteristic, build_valve
from mech_regulator.scene import governor_keys

Mode = tuple[str, str]
# A machine's mode (model.machine): its governor's Mode, if it has a governor, then its drive train's, if any; None
# for a machine with neither.
MachineMode = tuple[str, ...]
ARM, ARM_RATE, SERVO, SHIFT = 2, 3, 4, 5  # indices of the governor's states in the full state vector


@dataclass(frozen=True)
class Guard:
    """A condition of a mode: value(y) >= 0 while the mode holds; when it turns negative the solver
    applies transition(y) -> (new mode, state to restart from). A timed guard's value and transition
    also read the time: value(t, y), transition(t, y) (a moment that changes in time, such as the
    external load, takes part in it)."""

    name: str
    value: Callable[..., float]
    transition: Callable[..., tuple[MachineMode | None, np.ndarray]]
    timed: bool = False

    def level(self, t: float, y: np.ndarray) -> float:
        """The guard's value at time t [s] and state y."""
        return self.value(t, y) if self.timed else self.value(y)

    def apply(self, t: float, y: np.ndarray) -> tuple[MachineMode | None, np.ndarray]:
        """The guard's transition at time t [s] from state y: (new mode, state to restart from)."""
        return self.transition(t, y) if self.timed else self.transition(y)


@dataclass(frozen=True)
class Governor:
    """A governor assembled from its scene entry.

    sensor: the centrifugal sensor (governors/sensor.py); valve: throttle(z) for direct action (None for indirect);
    pilot_neutral [m], servo_gain [1/(m s)], servo_max_speed [1/s] (inf = unlimited), dead_band [m],
    travel (low, high) [-], feedback ('none' | 'rigid' | 'isodromic'), feedback_gain rho [m],
    feedback_time_constant T_i [s], feedback_reference: servo position of rigid feedback's neutral [-];
    valve_breaks: the sleeve positions [m] where a valve table's slope jumps (build_valve).
    """

    kind: str
    sensor: CentrifugalSensor
    valve: ValveCharacteristic | None
    valve_formula: str
    pilot_neutral: float = math.nan
    servo_gain: float = 0.0
    servo_max_speed: float = math.inf
    dead_band: float = 0.0
    travel: tuple[float, float] = (0.0, 1.0)
    feedback: str = "none"
    feedback_gain: float = 0.0
    feedback_time_constant: float = math.inf
    valve_breaks: tuple[float, ...] = ()
    feedback_reference: float = 0.0

    @property
    def state_names(self) -> tuple[str, ...]:
        """Names of the governor's states in y[2:]."""
        names: tuple[str, ...] = ("arm_angle", "arm_rate")
        if self.kind == "indirect":
            names += ("servo",)
            if self.feedback == "isodromic":
                names += ("feedback_shift",)
        return names

    @property
    def has_friction(self) -> bool:
        return self.sensor.kinetic_friction > 0.0 or self.sensor.static_friction > 0.0

    def throttle(self, y: np.ndarray) -> float:
        """Throttle 0..1: the valve at the sleeve position (direct) or the servo position (indirect)."""
        if self.valve is not None:
            return self.valve(self.sensor.sleeve(y[ARM]))
        return y[SERVO]

    def held_throttle(self, anchor: float) -> Callable[[np.ndarray], float]:
        """y -> throttle 0..1 of a valve table continued along the piece that holds the sleeve position anchor [m]
        (between two of its breakpoints valve_breaks: smooth in y, the breakpoint met only by restarting on it)."""
        valve, sleeve = self.valve, self.sensor.sleeve
        assert valve is not None, "held_throttle reads a direct-action governor's valve"
        return lambda y: valve(sleeve(y[ARM]), anchor)

    def set_speed(self) -> float:
        """Indirect action: the crank speed [rad/s] at which the sleeve sits at pilot_neutral (no feedback
        shift); the speed held without droop. NaN for direct action."""
        return self.sensor.equilibrium_speed(self.pilot_neutral) if self.kind == "indirect" else math.nan

    def pilot_opening(self, y: np.ndarray) -> float:
        """Pilot-valve opening [m]: z - pilot_neutral, plus rho (s - s_ref) for rigid feedback or the
        dashpot's shift zeta for isodromic feedback. Positive opening closes the throttle."""
        opening = self.sensor.sleeve(y[ARM]) - self.pilot_neutral
        if self.feedback == "rigid":
            opening += servo_motor.rigid_feedback(self.feedback_gain, y[SERVO], self.feedback_reference)
        elif self.feedback == "isodromic":
            opening += y[SHIFT]
        return opening

    def servo_command(self, y: np.ndarray, ideal: bool = False) -> float:
        """Servo speed the pilot valve asks for [1/s]: s' = -gain * opening, less the dead band, clipped
        to +-max_speed. ideal: without dead band and speed limit (for the linearisation)."""
        opening = self.pilot_opening(y)
        if ideal:
            return -self.servo_gain * opening
        return servo_motor.servo_command(opening, self.servo_gain, self.servo_max_speed, self.dead_band)

    def initial_state(
        self, omega: float, sleeve: float | None, servo: float | None, balance_throttle: Callable[[float], float]
    ) -> np.ndarray:
        """The governor's states at t = 0: the sleeve at rest at `sleeve` or, by default, at its equilibrium
        for the initial speed; the servo at `servo` or at the throttle that balances the load at that
        speed (clipped to its travel); no dashpot shift."""
        z = self.sensor.equilibrium_sleeve(omega) if sleeve is None else sleeve
        state = [self.sensor.arm_angle(z), 0.0]
        if self.kind == "indirect":
            s = balance_throttle(omega) if servo is None else servo
            state.append(min(max(s, self.travel[0]), self.travel[1]))
            if self.feedback == "isodromic":
                state.append(0.0)
        return np.array(state)

    # ---------------------------------------------------------------------------------------------
    # Modes

    def initial_mode(self, y: np.ndarray) -> Mode:
        """The mode of a state at rest (arm rate 0): on a stop, stuck, or moving off as the forces say."""
        return self._sleeve_at_rest(y), self._servo_at_rest(y) if self.kind == "indirect" else ""

    def _sleeve_at_rest(self, y: np.ndarray) -> str:
        sensor = self.sensor
        low, high = sensor.stop_angles()
        force = sensor.lift(y[ARM], y[1])
        if y[ARM] <= low and force <= sensor.static_friction:
            return "low"
        if y[ARM] >= high and force >= -sensor.static_friction:
            return "high"
        if not self.has_friction:
            return "free"
        if force > sensor.static_friction:
            return "up"
        if force < -sensor.static_friction:
            return "down"
        return "stuck"

    def _servo_at_rest(self, y: np.ndarray) -> str:
        command = self.servo_command(y)
        if y[SERVO] <= self.travel[0] and command <= 0.0:
            return "low"
        if y[SERVO] >= self.travel[1] and command >= 0.0:
            return "high"
        return "free"

    def derivatives(self, mode: Mode | None, ideal: bool = False) -> Callable[[np.ndarray], list[float]]:
        """Time derivatives of the governor's states in a mode, as a function of the full state y.

        Sleeve: a' = arm_rate, a'' from the sensor's arm_acceleration with friction +F_k ('up'),
        -F_k ('down') or none ('free'); frozen when stuck or on a stop. Servo: s' = servo_command, 0 on a
        stop; isodromic dashpot: T_i zeta' + zeta = rho T_i s'. ideal: frictionless, no dead band, no
        speed limit, no stops (the smooth model that is linearised); mode None only with ideal.
        """
        sensor = self.sensor
        if ideal:
            sleeve_mode, servo_mode = "free", "free" if self.kind == "indirect" else ""
        else:
            assert mode is not None, "Governor.derivatives reads a mode unless ideal"
            sleeve_mode, servo_mode = mode
        friction = {"up": sensor.kinetic_friction, "down": -sensor.kinetic_friction, "free": 0.0}.get(sleeve_mode)
        moving_servo = servo_mode == "free"
        rho, time_constant = self.feedback_gain, self.feedback_time_constant

        def sleeve_part(y: np.ndarray) -> list[float]:
            if friction is None:
                return [0.0, 0.0]
            return [y[ARM_RATE], sensor.arm_acceleration(y[ARM], y[ARM_RATE], y[1], friction)]

        if self.kind == "direct":
            return sleeve_part

        def indirect(y: np.ndarray) -> list[float]:
            rates = sleeve_part(y)
            servo_rate = self.servo_command(y, ideal) if moving_servo else 0.0
            rates.append(servo_rate)
            if self.feedback == "isodromic":
                rates.append(servo_motor.isodromic_rate(rho, servo_rate, y[SHIFT], time_constant))
            return rates

        return indirect

    def guards(self, mode: Mode) -> list[Guard]:
        """The guards of a mode (see the module docstring)."""
        sensor = self.sensor
        low, high = sensor.stop_angles()
        static = sensor.static_friction
        sliding_up = "up" if self.has_friction else "free"
        sliding_down = "down" if self.has_friction else "free"

        def lift(y: np.ndarray) -> float:
            return sensor.lift(y[ARM], y[1])

        def to_stop(angle: float, stop_mode: str) -> Callable:
            def transition(y: np.ndarray) -> tuple[Mode, np.ndarray]:
                y = y.copy()
                y[ARM], y[ARM_RATE] = angle, 0.0
                return (stop_mode, mode[1]), y

            return transition

        def start(new_mode: str) -> Callable:
            def transition(y: np.ndarray) -> tuple[Mode, np.ndarray]:
                y = y.copy()
                y[ARM_RATE] = 0.0
                return (new_mode, mode[1]), y

            return transition

        def come_to_rest(y: np.ndarray) -> tuple[Mode, np.ndarray]:
            y = y.copy()
            y[ARM_RATE] = 0.0
            return (self._sleeve_at_rest(y), mode[1]), y

        hit_low = Guard("sleeve reaches the low stop", lambda y: y[ARM] - low, to_stop(low, "low"))
        hit_high = Guard("sleeve reaches the high stop", lambda y: high - y[ARM], to_stop(high, "high"))
        sleeve_guards = {
            "free": [hit_low, hit_high],
            "up": [Guard("sleeve stops rising", lambda y: y[ARM_RATE], come_to_rest), hit_high],
            "down": [Guard("sleeve stops falling", lambda y: -y[ARM_RATE], come_to_rest), hit_low],
            "stuck": [
                Guard("sleeve breaks away upwards", lambda y: static - lift(y), start(sliding_up)),
                Guard("sleeve breaks away downwards", lambda y: static + lift(y), start(sliding_down)),
            ],
            "low": [Guard("sleeve leaves the low stop", lambda y: static - lift(y), start(sliding_up))],
            "high": [Guard("sleeve leaves the high stop", lambda y: static + lift(y), start(sliding_down))],
        }[mode[0]]
        if self.kind == "direct":
            return sleeve_guards

        def servo_to(new_mode: str, position: float | None) -> Callable:
            def transition(y: np.ndarray) -> tuple[Mode, np.ndarray]:
                y = y.copy()
                if position is not None:
                    y[SERVO] = position
                return (mode[0], new_mode), y

            return transition

        s_low, s_high = self.travel
        servo_guards = {
            "free": [
                Guard("servo reaches its low stop", lambda y: y[SERVO] - s_low, servo_to("low", s_low)),
                Guard("servo reaches its high stop", lambda y: s_high - y[SERVO], servo_to("high", s_high)),
            ],
            "low": [Guard("servo leaves its low stop", lambda y: -self.servo_command(y), servo_to("free", None))],
            "high": [Guard("servo leaves its high stop", lambda y: self.servo_command(y), servo_to("free", None))],
        }[mode[1]]
        return sleeve_guards + servo_guards

    def signals(self, y: np.ndarray) -> dict[str, np.ndarray | float]:
        """The governor's outputs at state(s) y (one state, or states along the last axis) besides the throttle:
        sleeve z [m], sleeve_velocity z' [m/s], arm_angle [rad], arm_rate [rad/s] and its further states by name
        (servo [-], feedback_shift [m])."""
        sensor = self.sensor
        arm, arm_rate = y[ARM], y[ARM_RATE]
        values = {
            "sleeve": np.vectorize(sensor.sleeve, otypes=[float])(arm),
            "sleeve_velocity": np.vectorize(sensor.sleeve_rate, otypes=[float])(arm, arm_rate),
            "arm_angle": arm,
            "arm_rate": arm_rate,
        }
        for index, name in enumerate(self.state_names[2:], start=SERVO):
            values[name] = y[index]
        return values

    def describe(self) -> list[str]:
        """Lines for `describe`: the governor's parts and equations."""
        sensor = self.sensor
        lines = [
            f"{self.kind} governor, {sensor.describe()}",
            f"  sleeve: stroke {sensor.stroke[0]:g} to {sensor.stroke[1]:g} m (inelastic stops), damping "
            f"{sensor.damping:g} N s/m, friction {sensor.kinetic_friction:g} N (static {sensor.static_friction:g} N)",
        ]
        if self.kind == "direct":
            lines.append(f"  valve: {self.valve_formula}")
        else:
            lines.append(
                f"  pilot neutral at z = {self.pilot_neutral:g} m (set speed {self.set_speed():.4g} rad/s); "
                f"servo s' = -{self.servo_gain:g} * opening, |s'| <= {self.servo_max_speed:g} 1/s, dead band "
                f"{self.dead_band:g} m, travel {self.travel[0]:g}..{self.travel[1]:g}"
            )
            if self.feedback == "rigid":
                lines.append(f"  rigid feedback: opening += {self.feedback_gain:g} (s - {self.feedback_reference:.4g})")
            elif self.feedback == "isodromic":
                lines.append(
                    f"  isodromic feedback: opening += zeta, {self.feedback_time_constant:g} zeta' + zeta = "
                    f"{self.feedback_gain:g} * {self.feedback_time_constant:g} s'"
                )
            else:
                lines.append("  no feedback (expect hunting)")
        return lines


def build_governor(
    spec: governor_keys.Governor, balance_throttle: Callable[[float], float]
) -> Governor | ElectronicGovernor:
    """Assemble a scene's governor. balance_throttle(omega) is the throttle at which the cycle-averaged
    drive balances the initial load at crank speed omega; rigid feedback's default reference is its
    value at the set speed."""
    if isinstance(spec, governor_keys.PIGovernor):
        return ElectronicGovernor(
            set_point=spec.set_speed,
            gain=spec.gain,
            integral_time=spec.integral_time,
            travel=(spec.travel[0], spec.travel[1]),
        )
    sensor = build_sensor(spec)
    if not isinstance(spec, governor_keys.IndirectGovernor):
        valve, formula, breaks = build_valve(spec.valve)
        return Governor(kind="direct", sensor=sensor, valve=valve, valve_formula=formula, valve_breaks=breaks)
    servo, feedback = spec.servo, spec.feedback
    reference = feedback.reference
    if feedback.type == "rigid" and reference is None:
        reference = balance_throttle(sensor.equilibrium_speed(spec.pilot_neutral))
    return Governor(
        kind="indirect",
        sensor=sensor,
        valve=None,
        valve_formula="",
        pilot_neutral=spec.pilot_neutral,
        servo_gain=servo.gain,
        servo_max_speed=servo.max_speed or math.inf,
        dead_band=servo.dead_band,
        travel=(servo.travel[0], servo.travel[1]),
        feedback=feedback.type,
        feedback_gain=feedback.gain,
        feedback_time_constant=feedback.time_constant or math.inf,
        feedback_reference=reference or 0.0,
    )


class _SensorArguments(TypedDict):
    """The arguments every centrifugal sensor takes (governors.sensor.CentrifugalSensor's and the spring's)."""

    ball_mass: float
    sleeve_mass: float
    stiffness: float
    free_position: float
    damping: float
    kinetic_friction: float
    static_friction: float
    ratio: float
    gravity: float
    stroke: tuple[float, float]


def build_sensor(
    spec: governor_keys.DirectGovernor | governor_keys.IndirectGovernor | governor_keys.HartnellGovernor,
) -> CentrifugalSensor:
    """The centrifugal sensor of a scene's governor: Hartnell's for type 'hartnell', Porter's otherwise."""
    spring = spec.spring or governor_keys.SleeveSpring(stiffness=0.0)
    common = _SensorArguments(
        ball_mass=spec.ball_mass,
        sleeve_mass=spec.sleeve_mass,
        stiffness=spring.stiffness,
        free_position=spring.free_position,
        damping=spec.damping,
        kinetic_friction=spec.friction,
        static_friction=spec.friction if spec.static_friction is None else spec.static_friction,
        ratio=spec.ratio,
        gravity=spec.gravity,
        stroke=(spec.stroke[0], spec.stroke[1]),
    )
    if isinstance(spec, governor_keys.HartnellGovernor):
        return HartnellSensor(
            ball_arm=spec.ball_arm, sleeve_arm=spec.sleeve_arm, pivot_radius=spec.pivot_radius, **common
        )
    return PorterSensor(arm_length=spec.arm_length, **common)
