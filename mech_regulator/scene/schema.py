"""The scene format: one YAML file describing a machine, what acts on it, the scenario and the solver.

The pydantic models below are the single source of truth for the format: validation, the JSON
Schema (`mech-regulator schema`) and the key tables of `docs/scenes.md` all come from them.
Every field's description states its unit (SI unless the key name says `_deg`).

Conventions: the crank angle phi is measured counter-clockwise from the +x axis, the crank pin is
at `B = (R cos phi, R sin phi)`; positive moments turn the crank counter-clockwise (the working
direction); load values are resisting magnitudes unless a description says "signed".
"""

from __future__ import annotations

import math
from typing import Annotated, Literal, Union

from pydantic import BaseModel, ConfigDict, Discriminator, Field, Tag, model_validator

Positive = Annotated[float, Field(gt=0)]
NonNegative = Annotated[float, Field(ge=0)]


class SceneModel(BaseModel):
    """Base of every scene section: unknown keys, NaN and infinities are errors; ints pass as floats."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, strict=True, frozen=True)


def _check_table(angles_deg: list[float], values: list[float], period_deg: float, what: str) -> None:
    """Check a periodic table: equal lengths, strictly increasing angles inside one period."""
    if len(angles_deg) != len(values):
        raise ValueError(f"{what}: angle_deg has {len(angles_deg)} entries but the values have {len(values)}; "
                         "expected one value per angle")
    if any(b <= a for a, b in zip(angles_deg, angles_deg[1:])):
        raise ValueError(f"{what}: angle_deg = {angles_deg} must be strictly increasing")
    if angles_deg[-1] - angles_deg[0] >= period_deg:
        raise ValueError(f"{what}: angle_deg spans {angles_deg[-1] - angles_deg[0]} deg; "
                         f"expected less than one period ({period_deg} deg)")


# --------------------------------------------------------------------------------------------
# Machine: inertia and mechanism


class Flywheel(SceneModel):
    inertia: NonNegative = Field(description="moment of inertia of the flywheel about its own shaft [kg m^2]")
    ratio: float = Field(1.0, description="omega_flywheel / omega (gear ratio to the crank); the flywheel adds "
                                          "inertia * ratio^2 to the reduced inertia [-]")


class CrankSlider(SceneModel):
    """Crank–slider: crank pin B = R(cos phi, sin phi), slider on the line y = offset on the +x side."""

    type: Literal["crank_slider"]
    crank: Positive = Field(description="crank radius R [m]")
    rod: Positive = Field(description="connecting-rod length l [m]; must exceed crank + |offset|")
    offset: float = Field(0.0, description="offset e of the stroke line y = e (desaxe) [m]")
    crank_mass: NonNegative = Field(0.0, description="crank mass, used for its weight only (its inertia is in "
                                                     "machine.inertia) [kg]")
    crank_cg: float = Field(0.0, description="distance of the crank's centre of mass from the axis, towards the pin [m]")
    rod_mass: NonNegative = Field(0.0, description="connecting-rod mass [kg]")
    rod_cg: NonNegative = Field(0.0, description="distance of the rod's centre of mass from the crank pin, along the rod [m]")
    rod_inertia: NonNegative = Field(0.0, description="rod moment of inertia about its centre of mass [kg m^2]")
    slider_mass: NonNegative = Field(0.0, description="slider (piston) mass [kg]")

    @model_validator(mode="after")
    def _assembles(self) -> CrankSlider:
        reach = self.crank + abs(self.offset)
        if self.rod <= reach:
            raise ValueError(f"rod = {self.rod} m is too short: the crank turns fully only if rod > crank + |offset| "
                             f"= {reach:g} m")
        if self.rod_cg > self.rod:
            raise ValueError(f"rod_cg = {self.rod_cg} m lies beyond the rod (rod = {self.rod} m); "
                             "expected 0 <= rod_cg <= rod")
        return self


class FourBar(SceneModel):
    """Four-bar: crank a about A = (0, 0), coupler b, rocker c about D = frame * (cos th1, sin th1).

    Loop closure `a e^{i th2} + b e^{i th3} = d e^{i th1} + c e^{i th4}` with th2 = phi."""

    type: Literal["four_bar"]
    crank: Positive = Field(description="crank length a (A to B) [m]")
    coupler: Positive = Field(description="coupler length b (B to C) [m]")
    rocker: Positive = Field(description="rocker length c (D to C) [m]")
    frame: Positive = Field(description="frame length d (A to D) [m]")
    frame_angle_deg: float = Field(0.0, description="direction th1 of the frame line A->D from the +x axis [deg]")
    branch: Literal["open", "crossed"] = Field("open", description="assembly branch: 'open' puts C to the right "
                                                                    "of the directed line D->B, 'crossed' to the left")
    crank_mass: NonNegative = Field(0.0, description="crank mass, for its weight only [kg]")
    crank_cg: float = Field(0.0, description="distance of the crank's centre of mass from A towards B [m]")
    coupler_mass: NonNegative = Field(0.0, description="coupler mass [kg]")
    coupler_cg: float = Field(0.0, description="distance of the coupler's centre of mass from B towards C [m]")
    coupler_inertia: NonNegative = Field(0.0, description="coupler moment of inertia about its centre of mass [kg m^2]")
    rocker_mass: NonNegative = Field(0.0, description="rocker mass [kg]")
    rocker_cg: float = Field(0.0, description="distance of the rocker's centre of mass from D towards C [m]")
    rocker_inertia: NonNegative = Field(0.0, description="rocker moment of inertia about its centre of mass [kg m^2]")

    @model_validator(mode="after")
    def _assembles(self) -> FourBar:
        from mech_regulator.mechanisms.four_bar import unassemblable_crank_ranges

        ranges = unassemblable_crank_ranges(self.crank, self.coupler, self.rocker, self.frame,
                                            math.radians(self.frame_angle_deg))
        if ranges:
            spans = ", ".join(f"{math.degrees(lo):.2f} to {math.degrees(hi):.2f} deg" for lo, hi in ranges)
            raise ValueError(
                f"the four-bar (crank {self.crank}, coupler {self.coupler}, rocker {self.rocker}, frame {self.frame} m) "
                f"cannot be assembled for crank angles {spans}; the crank must turn fully: expected a Grashof "
                "crank (shortest link = crank, and shortest + longest < sum of the other two)")
        return self


Mechanism = Annotated[Union[CrankSlider, FourBar], Field(discriminator="type")]


# --------------------------------------------------------------------------------------------
# Drives (positive moments drive the crank)


class ConstantDrive(SceneModel):
    type: Literal["constant"]
    torque: float = Field(description="driving moment M_d on the crank, signed [N m]")


class LinearMotor(SceneModel):
    """Motor with a linear characteristic M = stall_torque * (1 - omega / no_load_speed)."""

    type: Literal["linear_motor"]
    stall_torque: Positive = Field(description="starting (stall) moment M0 at omega = 0 [N m]")
    no_load_speed: Positive = Field(description="speed omega0 at which the moment falls to zero [rad/s]")


class _TorqueTable(SceneModel):
    """Periodic table of a moment over the crank angle, linear between points."""

    angle_deg: list[float] = Field(min_length=2, description="crank angles of the table points [deg]")
    torque: list[float] = Field(min_length=2, description="driving moment at each angle, signed [N m]")
    period_deg: Positive = Field(360.0, description="period of the table in crank angle (720 for a four-stroke cycle) [deg]")

    @model_validator(mode="after")
    def _table(self) -> _TorqueTable:
        _check_table(self.angle_deg, self.torque, self.period_deg, "torque table")
        return self


class TableDrive(_TorqueTable):
    """Periodic table of the driving moment over the crank angle, linear between points."""

    type: Literal["table"]


class Engine(SceneModel):
    """Gas force of an engine cylinder acting on the slider of a crank–slider: F_x = -p(angle) * area."""

    type: Literal["engine"]
    bore: Positive = Field(description="cylinder bore; the piston area is pi bore^2 / 4 [m]")
    angle_deg: list[float] = Field(min_length=2, description="cycle angles of the indicator-diagram points, 0 = a top "
                                                            "dead centre at the start of intake [deg]")
    pressure: list[float] = Field(min_length=2, description="gauge gas pressure at each cycle angle [Pa]")
    cycle_deg: Literal[360.0, 720.0] = Field(720.0, description="length of the working cycle: 720 four-stroke, 360 two-stroke [deg]")
    phase_deg: float = Field(0.0, description="cycle angle at crank angle phi = 0 [deg]")

    @model_validator(mode="after")
    def _table(self) -> Engine:
        _check_table(self.angle_deg, self.pressure, self.cycle_deg, "engine pressure")
        return self


Drive = Annotated[Union[ConstantDrive, LinearMotor, TableDrive, Engine], Field(discriminator="type")]


# --------------------------------------------------------------------------------------------
# Loads


class ConstantLoad(SceneModel):
    type: Literal["constant"]
    torque: NonNegative = Field(description="resisting moment M_c, acting against the working direction: "
                                            "moment = -torque [N m]")


class ViscousLoad(SceneModel):
    type: Literal["viscous"]
    coefficient: NonNegative = Field(description="viscous coefficient c on the crank: moment = -c omega [N m s/rad]")


class FanLoad(SceneModel):
    type: Literal["fan"]
    coefficient: NonNegative = Field(description="fan coefficient k: moment = -k omega |omega| [N m s^2/rad^2]")


class TableLoad(_TorqueTable):
    """Periodic table of the resisting moment over the crank angle, linear between points."""

    type: Literal["table"]
    torque: list[float] = Field(min_length=2, description="resisting moment at each angle: moment = -torque [N m]")


class CuttingLoad(SceneModel):
    """On-off technological load (the lathe of physics.md section 2): -torque inside the intervals, 0 outside."""

    type: Literal["cutting"]
    torque: NonNegative = Field(description="resisting moment while cutting, F r [N m]")
    intervals_deg: list[list[float]] = Field(min_length=1, description="crank-angle intervals [start, end) in which "
                                                                        "the tool cuts, within one period [deg]")
    period_deg: Positive = Field(360.0, description="period of the cutting pattern [deg]")

    @model_validator(mode="after")
    def _intervals(self) -> CuttingLoad:
        flat = []
        for interval in self.intervals_deg:
            if len(interval) != 2 or interval[1] <= interval[0]:
                raise ValueError(f"intervals_deg entry {interval} must be [start, end] with end > start")
            flat += interval
        if any(b < a for a, b in zip(flat, flat[1:])) or flat[-1] - flat[0] > self.period_deg:
            raise ValueError(f"intervals_deg = {self.intervals_deg} must be sorted, not overlap, and lie within "
                             f"one period ({self.period_deg} deg)")
        return self


class SliderConstant(SceneModel):
    type: Literal["slider_constant"]
    force: float = Field(description="constant force on the slider along +x, signed [N]")


class RockerConstant(SceneModel):
    type: Literal["rocker_constant"]
    torque: float = Field(description="constant moment on the rocker, counter-clockwise positive, signed [N m]")


class OutputViscous(SceneModel):
    type: Literal["slider_viscous", "rocker_viscous"]
    coefficient: NonNegative = Field(description="viscous coefficient on the slider, -c v [N s/m], or on the rocker, "
                                                 "-c omega_rocker [N m s/rad]")


class OutputSpring(SceneModel):
    type: Literal["slider_spring", "rocker_spring"]
    stiffness: NonNegative = Field(description="spring stiffness on the slider, -k (x - x0) [N/m], or on the rocker, "
                                               "-k (theta4 - theta0) [N m/rad]")
    free_position: float = Field(0.0, description="free slider position x0 [m], or free rocker angle theta0 [rad]")


class SliderTable(SceneModel):
    """Force on the slider tabulated over its position, linear between points, constant beyond the ends."""

    type: Literal["slider_table"]
    position: list[float] = Field(min_length=2, description="slider positions x, strictly increasing [m]")
    force: list[float] = Field(min_length=2, description="signed force along +x at each position [N]")

    @model_validator(mode="after")
    def _table(self) -> SliderTable:
        if len(self.position) != len(self.force):
            raise ValueError(f"slider_table: {len(self.position)} positions but {len(self.force)} forces; "
                             "expected one force per position")
        if any(b <= a for a, b in zip(self.position, self.position[1:])):
            raise ValueError(f"slider_table: position = {self.position} must be strictly increasing")
        return self


Load = Annotated[
    Union[ConstantLoad, ViscousLoad, FanLoad, TableLoad, CuttingLoad, SliderConstant, RockerConstant, OutputViscous,
          OutputSpring, SliderTable],
    Field(discriminator="type"),
]


DrivenLoad = Annotated[Union[ConstantLoad, ViscousLoad, FanLoad, TableLoad, SliderConstant, RockerConstant,
                             OutputViscous, OutputSpring, SliderTable], Field(discriminator="type")]


class DrivenPart(SceneModel):
    """The driven part of a two-mass machine (physics.md section 4): a rotor with its own resisting moments,
    turning at omega_driven, angle phi_driven = phi - twist, optionally with a mechanism on its shaft (then
    I2(phi_driven) = inertia + the links' reduced inertia); the scenario's external load acts on it."""

    inertia: Positive = Field(description="constant part of the moment of inertia I2 of the driven part, reduced to "
                                          "the crank shaft [kg m^2]")
    mechanism: Mechanism | None = Field(None, description="linkage driven by the driven shaft (its crank angle is "
                                                          "phi_driven); adds its links' reduced inertia and weight "
                                                          "(machine.gravity)")
    loads: list[DrivenLoad] = Field(default_factory=list, description="resisting moments on the driven part, read "
                                                                      "at phi_driven and omega_driven (constant, "
                                                                      "viscous, fan, table in phi_driven, and "
                                                                      "slider/rocker loads of its mechanism)")

    @model_validator(mode="after")
    def _loads_fit_mechanism(self) -> DrivenPart:
        kind = self.mechanism.type if self.mechanism is not None else None
        needs = {"slider": "crank_slider", "rocker": "four_bar"}
        for index, load in enumerate(self.loads):
            prefix = load.type.split("_")[0]
            if prefix in needs and kind != needs[prefix]:
                raise ValueError(f"driven.loads[{index}] type '{load.type}' acts on the {prefix}: it needs "
                                 f"driven.mechanism.type: {needs[prefix]} (the driven part has "
                                 f"{kind or 'no mechanism'})")
        return self


class CouplingCharacteristic(SceneModel):
    """Nonlinear elastic characteristic M_m(twist) of a coupling: a table, linear between points; beyond the
    table the end segments continue (the coupling keeps its end stiffness)."""

    twist: list[float] = Field(min_length=2, description="twists phi - phi_driven of the table points, strictly "
                                                         "increasing, with a point at 0 [rad]")
    moment: list[float] = Field(min_length=2, description="elastic moment the coupling passes at each twist, "
                                                          "strictly increasing, 0 at twist 0 [N m]")

    @model_validator(mode="after")
    def _elastic(self) -> CouplingCharacteristic:
        if len(self.twist) != len(self.moment):
            raise ValueError(f"characteristic: twist has {len(self.twist)} entries but moment has "
                             f"{len(self.moment)}; expected one moment per twist")
        if any(b <= a for a, b in zip(self.twist, self.twist[1:])):
            raise ValueError(f"characteristic: twist = {self.twist} rad must be strictly increasing")
        if 0.0 not in self.twist or self.moment[self.twist.index(0.0)] != 0.0:
            raise ValueError(f"characteristic: twist = {self.twist} rad, moment = {self.moment} N m; expected the "
                             "point twist 0 -> moment 0 (an untwisted coupling passes no moment)")
        falls = [i for i, (a, b) in enumerate(zip(self.moment, self.moment[1:])) if b <= a]
        if falls:
            i = falls[0]
            raise ValueError(f"characteristic: moment does not rise from twist {self.twist[i]} to {self.twist[i + 1]} "
                             f"rad ({self.moment[i]} -> {self.moment[i + 1]} N m); expected a strictly increasing "
                             "moment (positive stiffness everywhere: a falling characteristic has no stable "
                             "equilibrium)")
        return self


class Coupling(SceneModel):
    """Elastic coupling between the crank (driving part) and the driven part: it passes the moment
    M_m = M_elastic(twist) + damping * (omega - omega_driven), twist = phi - phi_driven, with M_elastic =
    stiffness * twist (linear) or the tabulated characteristic."""

    stiffness: Positive | None = Field(None, description="torsional stiffness k of a linear coupling; give this or "
                                                         "characteristic [N m/rad]")
    characteristic: CouplingCharacteristic | None = Field(None, description="nonlinear elastic characteristic "
                                                                            "M_elastic(twist); give this or stiffness")
    damping: NonNegative = Field(0.0, description="torsional damping c of the coupling [N m s/rad]")
    driven: DrivenPart = Field(description="the driven part")

    @model_validator(mode="after")
    def _one_characteristic(self) -> Coupling:
        if (self.stiffness is None) == (self.characteristic is None):
            given = "both" if self.stiffness is not None else "neither"
            raise ValueError(f"coupling: {given} of stiffness and characteristic given; expected exactly one "
                             "(stiffness [N m/rad] for a linear coupling, characteristic {twist, moment} for a "
                             "nonlinear one)")
        return self


class Machine(SceneModel):
    """The machine reduced to its driving link (the crank)."""

    inertia: NonNegative = Field(description="constant part J0 of the reduced inertia about the crank axis (rotor, "
                                             "crank, gears) [kg m^2]")
    flywheel: Flywheel | None = Field(None, description="optional flywheel; adds inertia * ratio^2")
    gravity: list[float] | None = Field(None, min_length=2, max_length=2,
                                        description="gravity vector [gx, gy] in the mechanism plane; weights of the "
                                                    "links become reduced moments [m/s^2]")
    mechanism: Mechanism | None = Field(None, description="linkage driven by the crank; without one J is constant")
    drive: Drive | None = Field(None, description="driving moment M_d")
    loads: list[Load] = Field(default_factory=list, description="resisting moments and forces M_c")
    coupling: Coupling | None = Field(None, description="optional elastic coupling to a driven part (two-mass "
                                                        "machine); the external load then acts on the driven part")

    @model_validator(mode="after")
    def _effects_fit_mechanism(self) -> Machine:
        kind = self.mechanism.type if self.mechanism is not None else None
        needs = {"slider": "crank_slider", "rocker": "four_bar"}
        for index, load in enumerate(self.loads):
            prefix = load.type.split("_")[0]
            if prefix in needs and kind != needs[prefix]:
                raise ValueError(f"loads[{index}] type '{load.type}' acts on the {prefix}: it needs mechanism.type: "
                                 f"{needs[prefix]} (the machine has {kind or 'no mechanism'})")
        if isinstance(self.drive, Engine) and kind != "crank_slider":
            raise ValueError(f"drive type 'engine' pushes a piston: it needs mechanism.type: crank_slider "
                             f"(the machine has {kind or 'no mechanism'})")
        flywheel = self.flywheel.inertia * self.flywheel.ratio ** 2 if self.flywheel else 0.0
        if self.inertia + flywheel <= 0 and self.mechanism is None:
            raise ValueError("the machine has no inertia: give machine.inertia > 0 or a flywheel")
        return self


# --------------------------------------------------------------------------------------------
# Governor (physics.md section 3): a centrifugal sensor whose sleeve sets the throttle, directly
# through a valve or indirectly through a pilot valve and a servo-motor. M_d = throttle * M_drive.


class SleeveSpring(SceneModel):
    stiffness: NonNegative = Field(description="spring rate k; the spring pushes the sleeve down with k (z - "
                                               "free_position) [N/m]")
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
    throttle: list[float] = Field(min_length=2, description="throttle at each sleeve position, 0 (closed) to 1 (open) [-]")

    @model_validator(mode="after")
    def _table(self) -> TableValve:
        if len(self.sleeve) != len(self.throttle):
            raise ValueError(f"sleeve has {len(self.sleeve)} entries but throttle has {len(self.throttle)}; "
                             "expected one throttle value per sleeve position")
        if any(b <= a for a, b in zip(self.sleeve, self.sleeve[1:])):
            raise ValueError(f"sleeve = {self.sleeve} must be strictly increasing")
        if any(not 0.0 <= value <= 1.0 for value in self.throttle):
            raise ValueError(f"throttle = {self.throttle}; expected values between 0 and 1")
        return self


def _valve_type(value) -> str | None:
    return value.get("type", "linear") if isinstance(value, dict) else getattr(value, "type", None)


Valve = Annotated[Union[Annotated[LinearValve, Tag("linear")], Annotated[TableValve, Tag("table")]],
                  Discriminator(_valve_type)]


class _CentrifugalGovernor(SceneModel):
    """Porter-type centrifugal sensor: two balls on arms of length l (links equal to the arms), sleeve rise
    z = 2 l (1 - cos a); Watt's governor is sleeve_mass 0, a spring-loaded one adds a spring."""

    ball_mass: Positive = Field(description="mass m of each of the two balls [kg]")
    arm_length: Positive = Field(description="arm (and link) length l [m]")
    sleeve_mass: NonNegative = Field(0.0, description="sleeve mass M; 0 = Watt's governor [kg]")
    spring: SleeveSpring | None = Field(None, description="optional spring on the sleeve")
    damping: NonNegative = Field(0.0, description="viscous damping on the sleeve, force c z' [N s/m]")
    friction: NonNegative = Field(0.0, description="Coulomb (kinetic) friction force on the moving sleeve [N]")
    static_friction: NonNegative | None = Field(None, description="friction force the sleeve must overcome to start "
                                                                  "moving; none = friction [N]")
    ratio: Positive = Field(1.0, description="spindle speed / crank speed [-]")
    stroke: list[float] = Field([0.01, 0.08], min_length=2, max_length=2,
                                description="sleeve travel [z_low, z_high] between inelastic hard stops [m]")
    gravity: Positive = Field(9.81, description="gravity along the spindle [m/s^2]")

    @model_validator(mode="after")
    def _sensor(self) -> _CentrifugalGovernor:
        low, high = self.stroke
        if not 0.0 < low < high < 2.0 * self.arm_length:
            raise ValueError(
                f"stroke = {self.stroke} m; expected 0 < z_low < z_high < 2 arm_length = {2 * self.arm_length:g} m "
                "(at z = 0 the arms hang along the spindle and the balls have no lever to lift the sleeve; at "
                "z = 2 arm_length the arms are horizontal)")
        if self.static_friction is not None and self.static_friction < self.friction:
            raise ValueError(f"static_friction = {self.static_friction} N is below friction = {self.friction} N; "
                             "expected static_friction >= friction")
        return self


class DirectGovernor(_CentrifugalGovernor):
    """Direct action: the sleeve moves the regulating element (valve) itself."""

    type: Literal["direct"]
    valve: Valve = Field(description="throttle as a function of the sleeve position")


class Servo(SceneModel):
    """Hydraulic servo-motor: piston speed proportional to the pilot-valve opening."""

    gain: Positive = Field(description="servo speed per pilot-valve opening: throttle' = -gain * opening [1/(m s)]")
    max_speed: Positive | None = Field(None, description="largest servo speed; none = unlimited [1/s]")
    dead_band: NonNegative = Field(0.0, description="pilot-valve overlap: openings smaller than this move nothing [m]")
    travel: list[float] = Field([0.0, 1.0], min_length=2, max_length=2,
                                description="servo travel [low, high] in throttle, between hard stops, within 0..1 [-]")

    @model_validator(mode="after")
    def _travel(self) -> Servo:
        low, high = self.travel
        if not 0.0 <= low < high <= 1.0:
            raise ValueError(f"travel = {self.travel}; expected 0 <= low < high <= 1 (throttle)")
        return self


class Feedback(SceneModel):
    """Feedback from the servo to the pilot valve: none (hunts), rigid (droop) or isodromic (astatic)."""

    type: Literal["none", "rigid", "isodromic"] = Field("none", description="kind of feedback")
    gain: NonNegative = Field(0.0, description="pilot-valve shift per unit of servo travel, rho [m]")
    time_constant: Positive | None = Field(None, description="isodromic dashpot time constant T_i [s]")
    reference: float | None = Field(None, description="rigid feedback: servo position at which the pilot is neutral "
                                                      "at pilot_neutral; none = the throttle that balances the "
                                                      "initial load at the set speed [-]")

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
    pilot_neutral: float = Field(description="sleeve position at which the pilot valve is closed; sets the speed "
                                             "the governor holds [m]")
    servo: Servo = Field(description="the servo-motor")
    feedback: Feedback = Field(default_factory=Feedback, description="feedback from the servo to the pilot valve")

    @model_validator(mode="after")
    def _pilot_in_stroke(self) -> IndirectGovernor:
        low, high = self.stroke
        if not low < self.pilot_neutral < high:
            raise ValueError(f"pilot_neutral = {self.pilot_neutral} m lies outside the stroke {self.stroke} m; "
                             "expected a sleeve position strictly inside it")
        return self


Governor = Annotated[Union[DirectGovernor, IndirectGovernor], Field(discriminator="type")]


# --------------------------------------------------------------------------------------------
# Scenario and solver


class InitialState(SceneModel):
    phi: float = Field(0.0, description="initial crank angle [rad]")
    omega: float = Field(0.0, description="initial crank speed [rad/s]")
    sleeve: float | None = Field(None, description="initial governor sleeve position z, at rest; none = the "
                                                   "equilibrium position at the initial speed [m]")
    servo: float | None = Field(None, description="initial servo-motor position (throttle, indirect governor); none = "
                                                  "the throttle that balances the initial load at the initial speed [-]")
    twist: float | None = Field(None, description="initial twist phi - phi_driven of the coupling, driven part turning "
                                                  "at omega; none = the static twist that carries the driven part's "
                                                  "loads at the initial speed [rad]")


class LoadEvent(SceneModel):
    """A change of the external load moment (opposing motion) at a time, as a step or a linear ramp."""

    time: NonNegative = Field(description="time at which the change starts [s]")
    torque: float = Field(description="new external load moment reached at time + ramp; moment = -torque [N m]")
    ramp: NonNegative = Field(0.0, description="duration of a linear ramp to the new value; 0 = step [s]")


class Scenario(SceneModel):
    initial: InitialState = Field(default_factory=InitialState, description="initial state of the crank")
    duration: Positive = Field(description="simulated time [s]")
    external_load: float = Field(0.0, description="external load moment at t = 0, opposing motion: moment = -value [N m]")
    load_events: list[LoadEvent] = Field(default_factory=list, description="changes of the external load in time")

    @model_validator(mode="after")
    def _events_in_order(self) -> Scenario:
        end_previous = 0.0
        for index, event in enumerate(self.load_events):
            if event.time < end_previous:
                raise ValueError(f"load_events[{index}].time = {event.time} s starts before the previous change ends "
                                 f"({end_previous} s); expected events in time order that do not overlap")
            end_previous = event.time + event.ramp
            if end_previous > self.duration:
                raise ValueError(f"load_events[{index}] ends at {end_previous} s, after the scenario's duration "
                                 f"{self.duration} s")
        return self


class Solver(SceneModel):
    method: Literal["RK45", "RK23", "DOP853", "Radau", "BDF", "LSODA", "RK4", "energy"] = Field(
        "DOP853", description="scipy.integrate method (adaptive, in time), RK4 (fixed step in time) or energy (the "
                              "textbook energy method, fixed step in phi)")
    rtol: Positive = Field(1e-8, description="relative tolerance of the adaptive methods [-]")
    atol: Positive = Field(1e-10, description="absolute tolerance of the adaptive methods, on phi [rad] and omega [rad/s]")
    max_step: Positive | None = Field(None, description="largest step of the adaptive methods; none = unlimited [s]")
    step: Positive = Field(1e-4, description="time step of RK4 [s]")
    phi_step_deg: Positive = Field(1.0, description="crank-angle step of the energy method [deg]")
    sample_rate: Positive = Field(1000.0, description="rate of the output samples (dense output) [Hz]")


class Analysis(SceneModel):
    steady_tolerance: Positive = Field(1e-4, description="steady when omega at the start of successive dynamic periods "
                                                         "differs by less than this fraction of omega_m [-]")
    settling_band: Positive = Field(0.002, description="a load change has settled once the cycle-mean speed stays "
                                                       "within this fraction of the new steady speed [-]")
    permitted_delta: Positive | None = Field(None, description="coefficient of speed fluctuation "
                                                             "(omega_max - omega_min) / omega_m that the machine's class "
                                                             "permits [-], e.g. 0.0125 (1/80) for an engine driving a "
                                                             "generator; recordings draw the band omega_set (1 +- "
                                                             "delta / 2) around the set speed")


class Scene(SceneModel):
    """A complete scene: machine, scenario, solver and analysis settings."""

    name: str | None = Field(None, description="short name of the scene, used in outputs")
    description: str | None = Field(None, description="free text describing the scene")
    machine: Machine = Field(description="the machine reduced to its crank")
    governor: Governor | None = Field(None, description="centrifugal speed governor; its throttle scales the drive")
    scenario: Scenario = Field(description="initial state, duration and load changes")
    solver: Solver = Field(default_factory=Solver, description="integration method and accuracy")
    analysis: Analysis = Field(default_factory=Analysis, description="settings of the post-run analysis")

    @model_validator(mode="after")
    def _governed(self) -> Scene:
        initial = self.scenario.initial
        if self.machine.coupling is None and initial.twist is not None:
            raise ValueError("scenario.initial.twist is set but the machine has no coupling")
        if self.machine.coupling is not None and self.solver.method == "energy":
            raise ValueError("solver.method 'energy' steps one crank angle; a machine with a coupling has two "
                             "masses: use a method in time (Radau or BDF for a stiff coupling, else DOP853)")
        if self.governor is None:
            for key in ("sleeve", "servo"):
                if getattr(initial, key) is not None:
                    raise ValueError(f"scenario.initial.{key} is set but the scene has no governor")
            return self
        if self.machine.drive is None:
            raise ValueError("the governor scales the driving moment, but machine.drive is missing")
        if self.solver.method == "energy":
            raise ValueError("solver.method 'energy' integrates the machine alone in phi; a governed scene needs a "
                             "method in time (DOP853, RK45, RK23, Radau, BDF, LSODA or RK4)")
        low, high = self.governor.stroke
        if initial.sleeve is not None and not low <= initial.sleeve <= high:
            raise ValueError(f"scenario.initial.sleeve = {initial.sleeve} m lies outside the governor's stroke "
                             f"{self.governor.stroke} m")
        if initial.servo is not None:
            if self.governor.type != "indirect":
                raise ValueError("scenario.initial.servo is set but the governor is 'direct' (it has no servo-motor)")
            low, high = self.governor.servo.travel
            if not low <= initial.servo <= high:
                raise ValueError(f"scenario.initial.servo = {initial.servo} lies outside the servo travel "
                                 f"{self.governor.servo.travel}")
        return self
