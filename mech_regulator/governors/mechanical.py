"""The centrifugal governor (docs/theory.md §8): a centrifugal sensor (governors/sensor.py: Porter's, Hartnell's) that
sets the throttle directly through a valve or through a servo-motor (governors/servo.py).

Its states in y are [a, a', (s, (zeta))]: the arm angle of the sensor and its rate, for indirect action the servo
position s (= throttle) and, with isodromic feedback, the dashpot's pilot shift zeta [m]. The drive is scaled,
M_d = throttle(y) M_drive.

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

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TypedDict

import numpy as np
from scipy import optimize

from mech_regulator.governors import servo as servo_motor
from mech_regulator.governors.centrifugal import PorterSensor
from mech_regulator.governors.hartnell import HartnellSensor
from mech_regulator.governors.kind import (
    AveragedMachine,
    GovernorKind,
    GovernorSource,
    Guard,
    LinearGuard,
    Mode,
    OperatingPoint,
    SourceWriter,
    builds,
    machine_speed,
)
from mech_regulator.governors.sensor import CentrifugalSensor
from mech_regulator.governors.valve import ValveCharacteristic, build_valve
from mech_regulator.scene import governor_keys

ARM, ARM_RATE, SERVO, SHIFT = 2, 3, 4, 5  # indices of the governor's states in the full state vector
# the mode codes of the fast path's generated module (mode_codes)
SLEEVE_CODE = {"": 0.0, "free": 0.0, "up": 1.0, "down": 2.0, "stuck": 3.0, "low": 4.0, "high": 5.0}
SERVO_CODE = {"": 0.0, "free": 0.0, "low": 1.0, "high": 2.0}


@dataclass(frozen=True)
class Governor(GovernorKind):
    """A centrifugal governor assembled from its scene entry: kind 'direct' or 'indirect' (its action).

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
    def state_units(self) -> tuple[str, ...]:
        """Units of the governor's states in y[2:]."""
        return ("rad", "rad/s", "-", "m")[: len(self.state_names)]

    @property
    def throttle_label(self) -> str:
        """The throttle's name in the recording: an indirect governor's is the servo position."""
        return "throttle = servo position s" if self.kind == "indirect" else "throttle"

    @property
    def vyshnegradsky_cubic(self) -> bool:
        """A direct governor's averaged loop is Vyshnegradsky's cubic."""
        return self.kind == "direct"

    @property
    def has_friction(self) -> bool:
        """Whether the sleeve has Coulomb friction."""
        return self.sensor.kinetic_friction > 0.0 or self.sensor.static_friction > 0.0

    def throttle(self, y: np.ndarray) -> float:
        """Throttle 0..1: the valve at the sleeve position (direct) or the servo position (indirect)."""
        if self.valve is not None:
            return self.valve(self.sensor.sleeve(y[ARM]))
        return y[SERVO]

    def valve_position(self, y: np.ndarray) -> float:
        """The sleeve position z [m] its valve reads."""
        return self.sensor.sleeve(y[ARM])

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

        (_, _, arm_acceleration), parameters = sensor.bound_kernels  # sensor.arm_acceleration without its calls

        def sleeve_part(y: np.ndarray) -> list[float]:
            if friction is None:
                return [0.0, 0.0]
            return [y[ARM_RATE], arm_acceleration(y[ARM], y[ARM_RATE], y[1], friction, *parameters)]

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
        if np.ndim(arm) == 0:  # one state (a node's every exchange): numpy's vectorize costs 10-20 us a call to set up
            sleeve, sleeve_velocity = sensor.sleeve(arm), sensor.sleeve_rate(arm, arm_rate)
        else:
            sleeve = np.vectorize(sensor.sleeve, otypes=[float])(arm)
            sleeve_velocity = np.vectorize(sensor.sleeve_rate, otypes=[float])(arm, arm_rate)
        values = {"sleeve": sleeve, "sleeve_velocity": sleeve_velocity, "arm_angle": arm, "arm_rate": arm_rate}
        for index, name in enumerate(self.state_names[2:], start=SERVO):
            values[name] = y[index]
        return values

    # ---------------------------------------------------------------------------------------------
    # The fast path

    def mode_codes(self, mode: Mode) -> tuple[float, float]:
        """(SLEEVE_CODE, SERVO_CODE) of a mode."""
        return SLEEVE_CODE[mode[0]], SERVO_CODE[mode[1]]

    def linear_guards(self, mode: Mode) -> list[LinearGuard | None]:
        """The stops (a - a_low, a_high - a; s - s_low, s_high - s) and the sleeve coming to rest (+-a') are linear in
        the state; break-away and leaving a stop are not."""
        low, high = self.sensor.stop_angles()
        hit_low: LinearGuard = (((ARM, 1.0),), -low)
        hit_high: LinearGuard = (((ARM, -1.0),), high)
        sleeve_rows: dict[str, list[LinearGuard | None]] = {
            "free": [hit_low, hit_high],
            "up": [(((ARM_RATE, 1.0),), 0.0), hit_high],
            "down": [(((ARM_RATE, -1.0),), 0.0), hit_low],
            "stuck": [None, None],
            "low": [None],
            "high": [None],
        }
        rows = sleeve_rows[mode[0]]
        if self.kind == "indirect":
            s_low, s_high = self.travel
            rows += [(((SERVO, 1.0),), -s_low), (((SERVO, -1.0),), s_high)] if mode[1] == "free" else [None]
        return rows

    def valve_table_state(self, breaks: tuple[float, ...]) -> tuple[tuple[tuple[int, float], ...], tuple[float, ...]]:
        """The arm angle a, and the arm angles of the sleeve positions `breaks` [m] (z rises with a)."""
        return ((ARM, 1.0),), tuple(self.sensor.arm_angle(z) for z in breaks)

    def source(self, writer: SourceWriter, valve_anchor: str) -> GovernorSource:
        """The sensor's kernels (CentrifugalSensor.kernels), the valve's formula (direct) or the servo's and its
        feedback's (indirect, governors/servo.py) compiled; the sleeve's and the servo's modes read from their codes."""
        sensor = self.sensor
        sleeve_kernel, lift_kernel, acceleration_kernel = writer.shared(*sensor.kernels())
        sensor_args = ", ".join(writer.scalar(value) for value in sensor.kernel_parameters())
        kinetic, static = writer.scalar(sensor.kinetic_friction), writer.scalar(sensor.static_friction)
        low, high = (writer.scalar(v) for v in sensor.stop_angles())
        z = f"{sleeve_kernel}(y[{ARM}], {sensor_args})"
        opening: list[str] = []
        command = ""
        if self.kind == "direct":
            throttle = writer.valve_call(z, valve_anchor)
        else:
            throttle = f"y[{SERVO}]"
            opening = [f"opening = {z} - {writer.scalar(self.pilot_neutral)}"]
            if self.feedback == "rigid":
                feedback = writer.formula_call(
                    servo_motor.rigid_feedback,
                    {"servo": f"y[{SERVO}]"},
                    {"gain": self.feedback_gain, "reference": self.feedback_reference},
                )
                opening.append(f"opening += {feedback}")
            elif self.feedback == "isodromic":
                opening.append(f"opening += y[{SHIFT}]")
            command = writer.formula_call(
                servo_motor.servo_command,
                {"opening": "opening"},
                {"gain": self.servo_gain, "max_speed": self.servo_max_speed, "dead_band": self.dead_band},
            )
        lift = f"{lift_kernel}(y[{ARM}], omega, {sensor_args})"
        sleeve_mode = writer.sleeve_mode
        rates = [
            f"sleeve_mode = {sleeve_mode}",
            "if sleeve_mode <= 2.0:",
            f"    friction = 0.0 if sleeve_mode == 0.0 else ({kinetic} if sleeve_mode == 1.0 else -{kinetic})",
            f"    dydt[{ARM}] = y[{ARM_RATE}]",
            f"    dydt[{ARM_RATE}] = {acceleration_kernel}(y[{ARM}], y[{ARM_RATE}], omega, friction, {sensor_args})",
            "else:",
            f"    dydt[{ARM}] = 0.0",
            f"    dydt[{ARM_RATE}] = 0.0",
        ]
        guards = [
            f"sleeve_mode = {sleeve_mode}",
            "if sleeve_mode == 0.0:",
            f"    levels[0] = y[{ARM}] - {low}",
            f"    levels[1] = {high} - y[{ARM}]",
            "    g = 2",
            "elif sleeve_mode == 1.0:",
            f"    levels[0] = y[{ARM_RATE}]",
            f"    levels[1] = {high} - y[{ARM}]",
            "    g = 2",
            "elif sleeve_mode == 2.0:",
            f"    levels[0] = -y[{ARM_RATE}]",
            f"    levels[1] = y[{ARM}] - {low}",
            "    g = 2",
            "elif sleeve_mode == 3.0:",
            f"    force = {lift}",
            f"    levels[0] = {static} - force",
            f"    levels[1] = {static} + force",
            "    g = 2",
            "elif sleeve_mode == 4.0:",
            f"    levels[0] = {static} - {lift}",
            "    g = 1",
            "else:",
            f"    levels[0] = {static} + {lift}",
            "    g = 1",
        ]
        if self.kind == "direct":
            return GovernorSource(throttle, rates, guards, 2)
        servo_mode = writer.servo_mode
        s_low, s_high = (writer.scalar(v) for v in self.travel)
        rates += opening + [
            f"servo_rate = {command} if {servo_mode} == 0.0 else 0.0",
            f"dydt[{SERVO}] = servo_rate",
        ]
        if self.feedback == "isodromic":
            rate = writer.formula_call(
                servo_motor.isodromic_rate,
                {"servo_rate": "servo_rate", "shift": f"y[{SHIFT}]"},
                {"gain": self.feedback_gain, "time_constant": self.feedback_time_constant},
            )
            rates.append(f"dydt[{SHIFT}] = {rate}")
        guards += (
            [
                f"if {servo_mode} == 0.0:",
                f"    levels[g] = y[{SERVO}] - {s_low}",
                f"    levels[g + 1] = {s_high} - y[{SERVO}]",
                "    g += 2",
                "else:",
            ]
            + [f"    {line}" for line in opening]
            + [
                f"    command = {command}",
                f"    levels[g] = -command if {servo_mode} == 1.0 else command",
                "    g += 1",
            ]
        )
        return GovernorSource(throttle, rates, guards, 4)

    # ---------------------------------------------------------------------------------------------
    # Statics and stability

    def operating_point(self, machine: AveragedMachine, external_load: float) -> OperatingPoint:
        """Solve throttle * M_d(omega) + M_c(omega) = 0 together with the governor's statics (docs/theory.md §8.6).

        direct: omega = omega(z) on the static characteristic, throttle = valve(z), one equation in z;
        indirect without or with isodromic feedback: z = pilot_neutral (astatic), throttle from the balance;
        rigid feedback: pilot closed at z = pilot_neutral - rho (s - s_ref), one equation in z.
        If the balance needs a sleeve or servo beyond its stops, the point sits on the stop and the speed
        follows from the machine's own balance at that throttle.
        """
        sensor = self.sensor
        valve = self.valve  # throttle(z) for direct action, None for indirect
        z_low, z_high = sensor.characteristic_range()
        mean_inertia = machine.cycle_averages(sensor.equilibrium_speed(z_low), external_load)[0]

        def surplus(throttle: float, omega: float) -> float:
            _, drive, other = machine.cycle_averages(omega, external_load)
            return throttle * drive + other

        def point(z: float, throttle: float, servo: float, limited: str = "") -> OperatingPoint:
            omega = sensor.equilibrium_speed(z)
            if limited:
                omega = machine_speed(lambda w: surplus(throttle, w), omega)
                if math.isnan(omega):
                    return OperatingPoint(
                        external_load,
                        omega,
                        z,
                        throttle,
                        servo,
                        f"{limited}; no steady speed at that throttle",
                        mean_inertia,
                    )
                z = sensor.equilibrium_sleeve(omega)
                if valve is not None:
                    throttle = valve(z)
            return OperatingPoint(external_load, omega, z, throttle, servo, limited, mean_inertia)

        if valve is not None:

            def balance(z: float) -> float:
                return surplus(valve(z), sensor.equilibrium_speed(z))

            if balance(z_high) > 0.0:
                return point(z_high, valve(z_high), math.nan, "sleeve on its high stop")
            if balance(z_low) < 0.0:
                return point(z_low, valve(z_low), math.nan, "sleeve on its low stop")
            z = optimize.brentq(balance, z_low, z_high, xtol=1e-14)
            return point(z, valve(z), math.nan)

        s_low, s_high = self.travel
        if self.feedback == "rigid":

            def servo_at(z: float) -> float:
                return self.feedback_reference - (z - self.pilot_neutral) / self.feedback_gain
        else:

            def servo_at(z: float) -> float:
                return machine.balance_throttle(sensor.equilibrium_speed(z), external_load)

        def balance_servo(z: float) -> float:
            return surplus(min(max(servo_at(z), s_low), s_high), sensor.equilibrium_speed(z))

        z = self.pilot_neutral
        if self.feedback == "rigid":
            for stop, name, outside in (
                (z_high, "high", balance_servo(z_high) > 0.0),
                (z_low, "low", balance_servo(z_low) < 0.0),
            ):
                if outside:
                    servo = min(max(servo_at(stop), s_low), s_high)
                    return point(stop, servo, servo, f"sleeve on its {name} stop")
            z = optimize.brentq(balance_servo, z_low, z_high, xtol=1e-14)
        servo = servo_at(z)
        if servo > s_high:
            return point(z, s_high, s_high, "servo on its high stop")
        if servo < s_low:
            return point(z, s_low, s_low, "servo on its low stop")
        return point(z, servo, servo)

    def equilibrium_state(self, point: OperatingPoint) -> np.ndarray:
        """[a, 0, (s, (0))]: the sleeve at rest at the point's position, the servo at its throttle, no shift."""
        x = [self.sensor.arm_angle(point.sleeve), 0.0]
        if self.kind == "indirect":
            x.append(point.servo)
            if self.feedback == "isodromic":
                x.append(0.0)
        return np.array(x)

    def state_scale(self, point: OperatingPoint) -> np.ndarray:
        """[1, 1, (1, (stroke's top z_high))]: a, a', s, zeta."""
        return np.array([1.0, 1.0, 1.0, self.sensor.stroke[1]])[: len(self.state_names)]

    def with_damping(self, damping: float) -> Governor:
        """The governor with its sensor's damping c [N s/m]."""
        # every CentrifugalSensor is a dataclass (PorterSensor, HartnellSensor); the ABC itself is not one
        sensor = dataclasses.replace(self.sensor, damping=damping)  # type: ignore[type-var]
        return dataclasses.replace(self, sensor=sensor)

    # ---------------------------------------------------------------------------------------------
    # What is shown

    def title(self) -> str:
        """'direct governor', 'indirect governor without feedback' or 'indirect governor, <kind> feedback'."""
        if self.kind == "direct":
            return "direct governor"
        if self.feedback == "none":
            return "indirect governor without feedback"
        return f"indirect governor, {self.feedback} feedback"

    def set_speed_text(self) -> str:
        """An indirect governor's set speed; a direct governor's moves with the load."""
        if self.kind == "indirect":
            return (
                f"Set speed ω_set = {self.set_speed():.6g} rad/s: the indirect governor's set speed "
                "(sleeve at the pilot valve's neutral). Throttle in 0..1: the servo position s."
            )
        return (
            "Set speed ω_set: where the direct governor settles under the present external load "
            "(operating point of the cycle-averaged machine; it moves with the load: the static "
            "error). Throttle in 0..1."
        )

    def plotted(self) -> tuple[str, str, float, str]:
        """The sleeve z in mm."""
        return "sleeve", "sleeve z", 1000.0, "mm"

    def joints(self) -> tuple[tuple[str, str, str | None], ...]:
        """sleeve (z, z'), arm (a, a'), throttle, then the servo and the dashpot's shift where it has them."""
        extra = tuple((name, name, None) for name in self.state_names[2:])
        return (
            ("sleeve", "sleeve", "sleeve_velocity"),
            ("arm", "arm_angle", "arm_rate"),
            ("throttle", "throttle", None),
            *extra,
        )

    def summary(self) -> dict[str, str | None]:
        """Its sensor's name and, for indirect action, its feedback."""
        return {"sensor": self.sensor.name, "feedback": self.feedback if self.kind == "indirect" else None}

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


@builds(governor_keys.DirectGovernor, governor_keys.IndirectGovernor, governor_keys.HartnellGovernor)
def build(
    spec: governor_keys.DirectGovernor | governor_keys.IndirectGovernor | governor_keys.HartnellGovernor,
    balance_throttle: Callable[[float], float],
) -> Governor:
    """A centrifugal governor of a scene's entry (Porter's sensor, or Hartnell's for type 'hartnell'): direct action
    through its valve, or indirect through a servo-motor. balance_throttle(omega) is the throttle at which the
    cycle-averaged drive balances the initial load at crank speed omega; rigid feedback's default reference is its
    value at the set speed."""
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
