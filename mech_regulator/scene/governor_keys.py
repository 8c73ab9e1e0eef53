"""The scene's `governor` keys: the valve (linear or a table), the centrifugal governors (direct, indirect with
its servo-motor and feedback, the spring-loaded Hartnell sensor) and the electronic PI governor."""

from __future__ import annotations

import math
from typing import Annotated, Literal

from pydantic import Discriminator, Field, Tag, model_validator

from mech_regulator.scene.key_types import NonNegative, Positive, SceneModel

# --------------------------------------------------------------------------------------------
# Governor (docs/theory.md §8): a centrifugal sensor whose sleeve sets the throttle, directly
# through a valve or indirectly through a pilot valve and a servo-motor. M_d = throttle * M_drive.


class SleeveSpring(SceneModel):
    stiffness: NonNegative = Field(
        description="spring rate k; the spring pushes the sleeve down with k (z - free_position) [N/m]"
    )
    free_position: float = Field(0.0, description="sleeve position z at which the spring is relaxed [m]")


class LinearValve(SceneModel):
    """Throttle linear in the sleeve position between two positions, clipped to 0..1."""

    type: Literal["linear"] = "linear"
    open_at: float = Field(description="sleeve position with the valve fully open, throttle 1 [m]")
    closed_at: float = Field(description="sleeve position with the valve closed, throttle 0 [m]")

    @model_validator(mode="after")
    def _distinct(self) -> LinearValve:
        if self.open_at == self.closed_at:
            raise ValueError(f"open_at = closed_at = {self.open_at} m; expected two different sleeve positions")
        return self


class TableValve(SceneModel):
    """Throttle as a table over the sleeve position, linear between points, held constant beyond them."""

    type: Literal["table"]
    sleeve: list[float] = Field(min_length=2, description="sleeve positions, strictly increasing [m]")
    throttle: list[float] = Field(
        min_length=2, description="throttle at each sleeve position, 0 (closed) to 1 (open) [-]"
    )

    @model_validator(mode="after")
    def _table(self) -> TableValve:
        if len(self.sleeve) != len(self.throttle):
            raise ValueError(
                f"sleeve has {len(self.sleeve)} entries but throttle has {len(self.throttle)}; "
                "expected one throttle value per sleeve position"
            )
        if any(b <= a for a, b in zip(self.sleeve, self.sleeve[1:])):
            raise ValueError(f"sleeve = {self.sleeve} must be strictly increasing")
        if any(not 0.0 <= value <= 1.0 for value in self.throttle):
            raise ValueError(f"throttle = {self.throttle}; expected values between 0 and 1")
        return self


def _valve_type(value) -> str | None:
    return value.get("type", "linear") if isinstance(value, dict) else getattr(value, "type", None)


Valve = Annotated[
    Annotated[LinearValve, Tag("linear")] | Annotated[TableValve, Tag("table")], Discriminator(_valve_type)
]


class _CentrifugalSensor(SceneModel):
    """What every centrifugal sensor has (governors/sensor.py): two balls, a sleeve with its spring, damping and
    friction, a spindle ratio and the sleeve's stroke between hard stops."""

    ball_mass: Positive = Field(description="mass m of each of the two balls [kg]")
    sleeve_mass: NonNegative = Field(0.0, description="sleeve mass M; 0 = Watt's governor [kg]")
    spring: SleeveSpring | None = Field(None, description="optional spring on the sleeve")
    damping: NonNegative = Field(0.0, description="viscous damping on the sleeve, force c z' [N s/m]")
    friction: NonNegative = Field(0.0, description="Coulomb (kinetic) friction force on the moving sleeve [N]")
    static_friction: NonNegative | None = Field(
        None, description="friction force the sleeve must overcome to start moving; none = friction [N]"
    )
    ratio: Positive = Field(1.0, description="spindle speed / crank speed [-]")
    stroke: list[float] = Field(
        [0.01, 0.08],
        min_length=2,
        max_length=2,
        description="sleeve travel [z_low, z_high] between inelastic hard stops [m]",
    )
    gravity: Positive = Field(9.81, description="gravity along the spindle [m/s^2]")

    @model_validator(mode="after")
    def _friction(self) -> _CentrifugalSensor:
        if self.static_friction is not None and self.static_friction < self.friction:
            raise ValueError(
                f"static_friction = {self.static_friction} N is below friction = {self.friction} N; "
                "expected static_friction >= friction"
            )
        return self


class _CentrifugalGovernor(_CentrifugalSensor):
    """Porter-type centrifugal sensor: two balls on arms of length l (links equal to the arms), sleeve rise
    z = 2 l (1 - cos a); Watt's governor is sleeve_mass 0, a spring-loaded one adds a spring."""

    arm_length: Positive = Field(description="arm (and link) length l [m]")

    @model_validator(mode="after")
    def _sensor(self) -> _CentrifugalGovernor:
        low, high = self.stroke
        if not 0.0 < low < high < 2.0 * self.arm_length:
            raise ValueError(
                f"stroke = {self.stroke} m; expected 0 < z_low < z_high < 2 arm_length = {2 * self.arm_length:g} m "
                "(at z = 0 the arms hang along the spindle and the balls have no lever to lift the sleeve; at "
                "z = 2 arm_length the arms are horizontal)"
            )
        return self


class DirectGovernor(_CentrifugalGovernor):
    """Direct action: the sleeve moves the regulating element (valve) itself."""

    type: Literal["direct"]
    valve: Valve = Field(description="throttle as a function of the sleeve position")


def _check_throttle_travel(travel: list[float]) -> None:
    """A travel [low, high] in throttle must lie within 0..1 with low < high."""
    low, high = travel
    if not 0.0 <= low < high <= 1.0:
        raise ValueError(f"travel = {travel}; expected 0 <= low < high <= 1 (throttle)")


class Servo(SceneModel):
    """Hydraulic servo-motor: piston speed proportional to the pilot-valve opening."""

    gain: Positive = Field(description="servo speed per pilot-valve opening: throttle' = -gain * opening [1/(m s)]")
    max_speed: Positive | None = Field(None, description="largest servo speed; none = unlimited [1/s]")
    dead_band: NonNegative = Field(0.0, description="pilot-valve overlap: openings smaller than this move nothing [m]")
    travel: list[float] = Field(
        [0.0, 1.0],
        min_length=2,
        max_length=2,
        description="servo travel [low, high] in throttle, between hard stops, within 0..1 [-]",
    )

    @model_validator(mode="after")
    def _travel(self) -> Servo:
        _check_throttle_travel(self.travel)
        return self


class Feedback(SceneModel):
    """Feedback from the servo to the pilot valve: none (hunts), rigid (droop) or isodromic (astatic)."""

    type: Literal["none", "rigid", "isodromic"] = Field("none", description="kind of feedback")
    gain: NonNegative = Field(0.0, description="pilot-valve shift per unit of servo travel, rho [m]")
    time_constant: Positive | None = Field(None, description="isodromic dashpot time constant T_i [s]")
    reference: float | None = Field(
        None,
        description="rigid feedback: servo position at which the pilot is neutral "
        "at pilot_neutral; none = the throttle that balances the "
        "initial load at the set speed [-]",
    )

    @model_validator(mode="after")
    def _complete(self) -> Feedback:
        if self.type != "none" and self.gain <= 0.0:
            raise ValueError(f"feedback type '{self.type}' needs gain > 0 (got {self.gain}) [m]")
        if self.type == "isodromic" and self.time_constant is None:
            raise ValueError("feedback type 'isodromic' needs time_constant (the dashpot's T_i) [s]")
        return self


class IndirectGovernor(_CentrifugalGovernor):
    """Indirect action: the sleeve moves a pilot valve; a servo-motor moves the regulating element.
    Pilot opening = z - pilot_neutral + feedback; the servo position is the throttle."""

    type: Literal["indirect"]
    pilot_neutral: float = Field(
        description="sleeve position at which the pilot valve is closed; sets the speed the governor holds [m]"
    )
    servo: Servo = Field(description="the servo-motor")
    feedback: Feedback = Field(default_factory=Feedback, description="feedback from the servo to the pilot valve")

    @model_validator(mode="after")
    def _pilot_in_stroke(self) -> IndirectGovernor:
        low, high = self.stroke
        if not low < self.pilot_neutral < high:
            raise ValueError(
                f"pilot_neutral = {self.pilot_neutral} m lies outside the stroke {self.stroke} m; "
                "expected a sleeve position strictly inside it"
            )
        return self


class HartnellGovernor(_CentrifugalSensor):
    """Direct action of a spring-loaded Hartnell sensor (governors/hartnell.py): two bell cranks pivoted at
    pivot_radius on the turning frame, each with a ball on its ball arm (upright at z = 0) and its sleeve arm
    (horizontal at z = 0) under the sleeve, which rises z = sleeve_arm sin theta; the spring pushes it down."""

    type: Literal["hartnell"]
    ball_arm: Positive = Field(description="length a of the bell crank's arm to the ball's centre [m]")
    sleeve_arm: Positive = Field(description="length b of the bell crank's arm to the sleeve [m]")
    pivot_radius: Positive = Field(description="radius r0 of the bell cranks' pivots from the spindle's axis [m]")
    spring: SleeveSpring = Field(description="the spring that pushes the sleeve down")
    stroke: list[float] = Field(
        min_length=2,
        max_length=2,
        description="sleeve travel [z_low, z_high] between inelastic hard stops, from the "
        "position with both arms square to the spindle [m]",
    )
    valve: Valve = Field(description="throttle as a function of the sleeve position")

    @model_validator(mode="after")
    def _sensor(self) -> HartnellGovernor:
        low, high = self.stroke
        if not -self.sleeve_arm < low < high < self.sleeve_arm:
            raise ValueError(
                f"stroke = {self.stroke} m; expected -sleeve_arm < z_low < z_high < sleeve_arm = "
                f"{self.sleeve_arm:g} m (at +-sleeve_arm the sleeve arms stand along the spindle)"
            )
        if self.pivot_radius <= self.ball_arm:
            raise ValueError(
                f"pivot_radius = {self.pivot_radius} m; expected more than ball_arm = {self.ball_arm} m "
                "(the balls would reach the spindle's axis)"
            )
        theta = math.asin(low / self.sleeve_arm)
        spring = self.spring.stiffness * (low - self.spring.free_position)
        pull = self.sleeve_arm * (
            self.sleeve_mass * self.gravity + spring
        ) - 2.0 * self.ball_mass * self.gravity * self.ball_arm * math.tan(theta)
        if pull <= 0.0:
            raise ValueError(
                f"spring = {self.spring.stiffness} N/m free at {self.spring.free_position} m does not "
                f"hold the sleeve down at its low stop z = {low} m against the balls' weights; expected "
                "sleeve_arm (sleeve_mass g + k (z_low - free_position)) > 2 ball_mass g ball_arm "
                "tan(theta_low)"
            )
        return self


class PIGovernor(SceneModel):
    """Electronic PI speed governor (governors/pi.py): it measures the crank speed and sets the throttle valve with
    throttle = x + gain (set_speed - omega) / set_speed within the travel, x' = gain e / integral_time."""

    type: Literal["pi"]
    set_speed: Positive = Field(description="crank speed the governor holds [rad/s]")
    gain: Positive = Field(
        description="proportional gain K_p: throttle per relative speed error (omega_s - omega) / omega_s [-]"
    )
    integral_time: Positive = Field(
        description="integral time T_i: x' = K_p e / T_i; also the anti-windup's tracking time on the valve's stops [s]"
    )
    travel: list[float] = Field(
        [0.0, 1.0], min_length=2, max_length=2, description="valve travel [low, high] in throttle, within 0..1 [-]"
    )

    @model_validator(mode="after")
    def _travel(self) -> PIGovernor:
        _check_throttle_travel(self.travel)
        return self


Governor = Annotated[DirectGovernor | IndirectGovernor | HartnellGovernor | PIGovernor, Field(discriminator="type")]
