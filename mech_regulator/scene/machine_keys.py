"""The scene's `machine` keys: the crank's inertia, flywheel, mechanism, drive and loads put together, with the
parts that join it to a second mass (branches, a driven part, a coupling, a clutch) and the friction of its joints
(journals, thrust collars); the checks that the loads and the joints fit the mechanism."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from mech_regulator.scene.effect_keys import BranchLoad, Drive, DrivenLoad, Engine, Load
from mech_regulator.scene.key_types import NonNegative, Positive, SceneModel
from mech_regulator.scene.mechanism_keys import CrankSlider, Linkage, Mechanism

# --------------------------------------------------------------------------------------------
# Machine: inertia and mechanism


class Flywheel(SceneModel):
    inertia: NonNegative = Field(description="moment of inertia of the flywheel about its own shaft [kg m^2]")
    ratio: float = Field(
        1.0,
        description="omega_flywheel / omega (gear ratio to the crank); the flywheel adds "
        "inertia * ratio^2 to the reduced inertia [-]",
    )


# The mechanism a load on its output (type slider_*, rocker_*, shuttle_*) needs.
OUTPUT_MECHANISM = {"slider": "crank_slider", "rocker": "four_bar", "shuttle": "walking_beam"}


def _check_loads_fit(loads: list, mechanism: Mechanism | None, key: str, owner: str) -> None:
    """Raise ValueError for a load on a mechanism's output whose mechanism (OUTPUT_MECHANISM) the owner (the
    machine or its driven part) does not have; key prefixes the scene keys named ('' or 'driven.')."""
    kind = mechanism.type if mechanism is not None else None
    linkage = mechanism if isinstance(mechanism, Linkage) else None
    for index, load in enumerate(loads):
        prefix = load.type.split("_")[0]
        needed = OUTPUT_MECHANISM.get(prefix)
        if needed is None or kind == needed or (linkage is not None and linkage.output_kind == prefix):
            continue
        if linkage is not None:
            has = {None: "no output", "slider": "output.joint", "rocker": "output.link"}[linkage.output_kind]
            wanted = {"slider": "output.joint (a prismatic joint)", "rocker": "output.link"}.get(prefix)
            raise ValueError(
                f"{key}loads[{index}] type '{load.type}' acts on the {prefix}: the linkage needs "
                f"{key}mechanism.{wanted or f'type: {needed}'} (it has {has})"
            )
        raise ValueError(
            f"{key}loads[{index}] type '{load.type}' acts on the {prefix}: it needs "
            f"{key}mechanism.type: {needed} ({owner} has {kind or 'no mechanism'})"
        )


class Branch(SceneModel):
    """A branch of a branched drive (docs/theory.md §7.4): a working member driven from the
    driven part's main shaft through a ratio i_1n, with its own inertia and resisting moments on its shaft."""

    name: str = Field(
        pattern=r"^[A-Za-z_][A-Za-z0-9_]*$",
        description="name of the branch, used in the output columns M_section_<name> (letters, digits, _)",
    )
    inertia: Positive = Field(
        description="moment of inertia I_n of everything beyond the branch's section, reduced "
        "to the branch's shaft [kg m^2]"
    )
    ratio: Positive = Field(
        description="ratio i_1n = omega_main / omega_n from the main shaft to the branch's shaft; "
        "the branch adds I_n / i_1n^2 to the main shaft's inertia [-]"
    )
    loads: list[BranchLoad] = Field(
        default_factory=list,
        description="resisting moments on the branch's shaft, of "
        "its speed omega_n = omega_driven / i_1n "
        "(constant, viscous, fan)",
    )


class DrivenPart(SceneModel):
    """The driven part of a two-mass machine (docs/theory.md §7.1): a rotor with its own resisting moments,
    turning at omega_driven, angle phi_driven = phi - twist, optionally with a mechanism on its shaft (then
    I2(phi_driven) = inertia + the links' reduced inertia), and branches; the scenario's external load acts on
    it. Its constant loads and the external load are Coulomb resistances: they oppose the motion and, at rest,
    hold the part up to their sum (it breaks away when the moment passed to it exceeds them)."""

    inertia: Positive = Field(
        description="constant part of the moment of inertia I2 of the driven part, reduced to the crank shaft [kg m^2]"
    )
    mechanism: Mechanism | None = Field(
        None,
        description="linkage driven by the driven shaft (its crank angle is "
        "phi_driven); adds its links' reduced inertia and weight "
        "(machine.gravity)",
    )
    loads: list[DrivenLoad] = Field(
        default_factory=list,
        description="resisting moments on the driven part, read "
        "at phi_driven and omega_driven (constant, "
        "viscous, fan, table in phi_driven, and "
        "slider/rocker loads of its mechanism)",
    )
    branches: list[Branch] = Field(
        default_factory=list,
        description="working members driven from the driven part's shaft (a branched drive), each with its ratio",
    )

    @model_validator(mode="after")
    def _loads_fit_mechanism(self) -> DrivenPart:
        names = [branch.name for branch in self.branches]
        repeated = sorted({name for name in names if names.count(name) > 1})
        if repeated:
            raise ValueError(f"branches: the name(s) {repeated} appear more than once; expected distinct names")
        _check_loads_fit(self.loads, self.mechanism, "driven.", "the driven part")
        return self


class CouplingCharacteristic(SceneModel):
    """Nonlinear elastic characteristic M_m(twist) of a coupling: a table, linear between points; beyond the
    table the end segments continue (the coupling keeps its end stiffness)."""

    twist: list[float] = Field(
        min_length=2,
        description="twists phi - phi_driven of the table points, strictly increasing, with a point at 0 [rad]",
    )
    moment: list[float] = Field(
        min_length=2,
        description="elastic moment the coupling passes at each twist, strictly increasing, 0 at twist 0 [N m]",
    )

    @model_validator(mode="after")
    def _elastic(self) -> CouplingCharacteristic:
        if len(self.twist) != len(self.moment):
            raise ValueError(
                f"characteristic: twist has {len(self.twist)} entries but moment has "
                f"{len(self.moment)}; expected one moment per twist"
            )
        if any(b <= a for a, b in zip(self.twist, self.twist[1:])):
            raise ValueError(f"characteristic: twist = {self.twist} rad must be strictly increasing")
        if 0.0 not in self.twist or self.moment[self.twist.index(0.0)] != 0.0:
            raise ValueError(
                f"characteristic: twist = {self.twist} rad, moment = {self.moment} N m; expected the "
                "point twist 0 -> moment 0 (an untwisted coupling passes no moment)"
            )
        falls = [i for i, (a, b) in enumerate(zip(self.moment, self.moment[1:])) if b <= a]
        if falls:
            i = falls[0]
            raise ValueError(
                f"characteristic: moment does not rise from twist {self.twist[i]} to {self.twist[i + 1]} "
                f"rad ({self.moment[i]} -> {self.moment[i + 1]} N m); expected a strictly increasing "
                "moment (positive stiffness everywhere: a falling characteristic has no stable "
                "equilibrium)"
            )
        return self


class Coupling(SceneModel):
    """Elastic coupling between the crank (driving part) and the driven part: it passes the moment
    M_m = M_elastic(twist) + damping * (omega - omega_driven), twist = phi - phi_driven, with M_elastic =
    stiffness * twist (linear) or the tabulated characteristic."""

    stiffness: Positive | None = Field(
        None, description="torsional stiffness k of a linear coupling; give this or characteristic [N m/rad]"
    )
    characteristic: CouplingCharacteristic | None = Field(
        None, description="nonlinear elastic characteristic M_elastic(twist); give this or stiffness"
    )
    damping: NonNegative = Field(0.0, description="torsional damping c of the coupling [N m s/rad]")
    driven: DrivenPart = Field(description="the driven part")

    @model_validator(mode="after")
    def _one_characteristic(self) -> Coupling:
        if (self.stiffness is None) == (self.characteristic is None):
            given = "both" if self.stiffness is not None else "neither"
            raise ValueError(
                f"coupling: {given} of stiffness and characteristic given; expected exactly one "
                "(stiffness [N m/rad] for a linear coupling, characteristic {twist, moment} for a "
                "nonlinear one)"
            )
        return self


class Journal(SceneModel):
    """A revolute joint's journal: its friction moment is M_f = lambda_p f' r |R| (docs/theory.md §6.2)."""

    radius: Positive = Field(description="journal (pin) radius r [m]")
    fit: Literal["clearance", "new", "run_in"] = Field(
        "clearance",
        description="pressure distribution over the "
        "journal: 'clearance' (lambda_p = 1), "
        "'new' close fit (pi/2), 'run_in' "
        "(4/pi) [-]",
    )


class Journals(SceneModel):
    """The revolute joints that have friction, by name; a joint left out turns without friction."""

    crank_bearing: Journal | None = Field(None, description="the crank's bearing A in the frame (both mechanisms)")
    crank_pin: Journal | None = Field(None, description="the crank pin B between crank and rod / coupler")
    wrist_pin: Journal | None = Field(None, description="crank_slider: the wrist pin C between rod and slider")
    rocker_pin: Journal | None = Field(None, description="four_bar: the pin C between coupler and rocker")
    rocker_bearing: Journal | None = Field(None, description="four_bar: the rocker's bearing D in the frame")


class ThrustCollar(SceneModel):
    """An annular thrust collar on the crank shaft carrying an axial load."""

    inner_radius: NonNegative = Field(description="inner radius r1 of the bearing ring [m]")
    outer_radius: Positive = Field(description="outer radius r2 of the bearing ring [m]")
    axial_load: NonNegative = Field(description="axial load Q on the collar [N]")
    state: Literal["new", "run_in"] = Field(
        "run_in",
        description="'new' (uniform pressure): M_f = 2/3 f Q (r2^3 - "
        "r1^3)/(r2^2 - r1^2); 'run_in' (uniform wear): "
        "M_f = f Q (r1 + r2)/2 [-]",
    )

    @model_validator(mode="after")
    def _ring(self) -> ThrustCollar:
        if self.inner_radius >= self.outer_radius:
            raise ValueError(
                f"thrust_collar: inner_radius = {self.inner_radius} m must be smaller than outer_radius "
                f"= {self.outer_radius} m"
            )
        return self


class JointFriction(SceneModel):
    """Coulomb friction in the joints, from the joint reactions of the kinetostatic analysis at every step
    (docs/theory.md §6.5; docs/joint_friction.md)."""

    coefficient: Positive = Field(description="coefficient of sliding friction f of the joints and the collar [-]")
    joints: Journals = Field(default_factory=Journals, description="the revolute joints with friction")
    journals: dict[str, Journal] = Field(
        default_factory=dict, description="linkage: its revolute joints with friction, by the joint's name"
    )
    guide: NonNegative = Field(
        0.0,
        description="crank_slider: coefficient of sliding friction of the slider on its "
        "guide, force f |N|; linkage: of every prismatic joint; 0 = none [-]",
    )
    thrust_collar: ThrustCollar | None = Field(None, description="optional thrust collar on the crank shaft")


JOINTS_OF: dict[str | None, tuple[str, ...]] = {
    "crank_slider": ("crank_bearing", "crank_pin", "wrist_pin"),
    "four_bar": ("crank_bearing", "crank_pin", "rocker_pin", "rocker_bearing"),
}
# Mechanisms whose kinetostatics is not built: only a thrust_collar can have friction.
NO_KINETOSTATICS = ("walking_beam", "multi-cylinder crank_slider")


class Clutch(SceneModel):
    """Friction (Coulomb) clutch between the crank side (machine.inertia, the motor of machine.drive) and the
    driven part: slipping it passes +-kinetic_torque (the sign of the slip); stuck, the two turn together and
    it passes the moment that keeps them together, as long as that stays within +-static_torque."""

    static_torque: Positive = Field(description="largest moment the stuck clutch can pass (static friction) [N m]")
    kinetic_torque: Positive = Field(
        description="moment the slipping clutch passes (kinetic friction); at most static_torque [N m]"
    )
    driven: DrivenPart = Field(description="the driven part (the working machine) behind the clutch")

    @model_validator(mode="after")
    def _kinetic_below_static(self) -> Clutch:
        if self.kinetic_torque > self.static_torque:
            raise ValueError(
                f"kinetic_torque = {self.kinetic_torque} N m exceeds static_torque = "
                f"{self.static_torque} N m; expected kinetic_torque <= static_torque"
            )
        if self.driven.mechanism is not None:
            raise ValueError(
                f"clutch.driven.mechanism ({self.driven.mechanism.type}): a driven part behind a clutch "
                "has no angle of its own in the state (only omega_driven), so it cannot carry a "
                "mechanism; expected a rotor (drop driven.mechanism, or use machine.coupling)"
            )
        for index, load in enumerate(self.driven.loads):
            if load.type not in ("constant", "viscous", "fan"):
                raise ValueError(
                    f"clutch.driven.loads[{index}] type '{load.type}' reads the driven part's angle, "
                    "which a driven part behind a clutch does not have; expected constant, viscous or "
                    "fan (angle-dependent driven loads need machine.coupling)"
                )
        return self


class Machine(SceneModel):
    """The machine reduced to its driving link (the crank)."""

    inertia: NonNegative = Field(
        description="constant part J0 of the reduced inertia about the crank axis (rotor, "
        "gears, a preset's crank; a linkage's crank counts in its link) [kg m^2]"
    )
    flywheel: Flywheel | None = Field(None, description="optional flywheel; adds inertia * ratio^2")
    gravity: list[float] | None = Field(
        None,
        min_length=2,
        max_length=2,
        description="gravity vector [gx, gy] in the mechanism plane; weights of the "
        "links become reduced moments [m/s^2]",
    )
    mechanism: Mechanism | None = Field(None, description="linkage driven by the crank; without one J is constant")
    drive: Drive | None = Field(None, description="driving moment M_d")
    loads: list[Load] = Field(default_factory=list, description="resisting moments and forces M_c")
    coupling: Coupling | None = Field(
        None,
        description="optional elastic coupling to a driven part (two-mass "
        "machine); the external load then acts on the driven part",
    )
    joint_friction: JointFriction | None = Field(
        None, description="optional friction in the mechanism's joints and a thrust collar (the most expensive effect)"
    )
    clutch: Clutch | None = Field(
        None,
        description="optional friction clutch to a driven part (motor and working "
        "machine); the external load then acts on the driven part",
    )

    def analysed_mechanism(self) -> tuple[Mechanism | None, bool]:
        """The mechanism whose kinematics and structure the commands analyse and the recording draws, and whether
        it is the driven part's: the machine's own, else the one behind a coupling, else None."""
        if self.mechanism is None and self.coupling is not None and self.coupling.driven.mechanism is not None:
            return self.coupling.driven.mechanism, True
        return self.mechanism, False

    @model_validator(mode="after")
    def _effects_fit_mechanism(self) -> Machine:
        kind = self.mechanism.type if self.mechanism is not None else None
        _check_loads_fit(self.loads, self.mechanism, "", "the machine")
        if isinstance(self.drive, Engine) and kind != "crank_slider":
            raise ValueError(
                f"drive type 'engine' pushes a piston: it needs mechanism.type: crank_slider "
                f"(the machine has {kind or 'no mechanism'})"
            )
        self._cylinders_fit_effects()
        flywheel = self.flywheel.inertia * self.flywheel.ratio**2 if self.flywheel else 0.0
        if self.inertia + flywheel <= 0 and self.mechanism is None:
            raise ValueError("the machine has no inertia: give machine.inertia > 0 or a flywheel")
        if self.joint_friction is not None:
            several = isinstance(self.mechanism, CrankSlider) and self.mechanism.cylinders is not None
            _check_joint_friction(self.joint_friction, "multi-cylinder crank_slider" if several else kind)
            if isinstance(self.mechanism, Linkage):
                _check_linkage_journals(self.joint_friction, self.mechanism)
        if self.joint_friction is not None and self.clutch is not None:
            raise ValueError(
                "machine.joint_friction with machine.clutch: the joint friction solves the crank's own "
                "equation, which a stuck clutch joins to the driven part; expected one of them"
            )
        if self.coupling is not None and self.clutch is not None:
            raise ValueError(
                "machine.coupling and machine.clutch are both set; the driven part sits behind one of "
                "them: expected either an elastic coupling or a friction clutch"
            )
        return self

    def _cylinders_fit_effects(self) -> None:
        """Several cylinders: forces on "the slider" are ambiguous (refused); firing keys need cylinders (that the
        firing fits the crankshaft is the mechanisms' check, mechanisms/checks.py)."""
        cylinders = self.mechanism.cylinders if isinstance(self.mechanism, CrankSlider) else None
        engine = self.drive if isinstance(self.drive, Engine) else None
        if cylinders is None:
            if engine is not None and (engine.firing_order or engine.firing_deg):
                raise ValueError("drive.firing_order / firing_deg need several cylinders: add mechanism.cylinders")
            return
        for index, load in enumerate(self.loads):
            if load.type.startswith("slider"):
                raise ValueError(
                    f"loads[{index}] type '{load.type}' acts on the slider, but the crank–slider has "
                    f"{len(cylinders)} cylinders (mechanism.cylinders): expected loads on the crank "
                    "(constant, viscous, fan, table, cutting)"
                )


def _check_linkage_journals(friction: JointFriction, linkage: Linkage) -> None:
    """A linkage's journals must name its revolute joints and its guide friction needs a prismatic joint (that its
    joint reactions are determinate is the mechanisms' check, mechanisms/checks.py)."""
    revolute = [name for name, joint in linkage.joints.items() if joint.type == "revolute"]
    foreign = [name for name in friction.journals if name not in revolute]
    if foreign:
        raise ValueError(
            f"joint_friction.journals names {foreign}, which are not revolute joints of the linkage; "
            f"expected some of {revolute}"
        )
    if friction.guide > 0.0 and len(revolute) == len(linkage.joints):
        raise ValueError(f"joint_friction.guide = {friction.guide}: the linkage has no prismatic joint to slide in")


def _check_joint_friction(friction: JointFriction, kind: str | None) -> None:
    """The joints named must exist in the mechanism, and something must have friction."""
    if friction.journals and kind != "linkage":
        raise ValueError(
            f"joint_friction.journals names {sorted(friction.journals)}: journals by joint name are a "
            f"linkage's (the machine has {kind or 'no mechanism'}); expected joint_friction.joints"
        )
    named = [name for name in Journals.model_fields if getattr(friction.joints, name) is not None]
    foreign = [name for name in named if name not in JOINTS_OF.get(kind, ())]
    if foreign:
        if kind in NO_KINETOSTATICS:
            expected = (
                f"none: the joint reactions of a {kind} are not computed (kinetostatics exists for a "
                "single crank_slider, the four_bar and a linkage); only a thrust_collar can have friction"
            )
        elif kind is None:
            expected = "none (a machine without a mechanism can only have a thrust_collar)"
        elif kind == "linkage":
            expected = "none: a linkage's journals are joint_friction.journals, by the names of its joints"
        else:
            expected = f"some of {list(JOINTS_OF[kind])}"
        raise ValueError(
            f"joint_friction.joints names {foreign}, which the machine's mechanism ({kind or 'none'}) "
            f"does not have; expected {expected}"
        )
    if friction.guide > 0.0 and kind not in ("crank_slider", "linkage"):
        raise ValueError(
            f"joint_friction.guide = {friction.guide}: only a crank_slider has a guide, or a linkage "
            f"its prismatic joints (the machine has {kind or 'no mechanism'})"
        )
    if not named and not friction.journals and friction.guide == 0.0 and friction.thrust_collar is None:
        raise ValueError("joint_friction has no joints, no guide and no thrust_collar: expected at least one of them")
