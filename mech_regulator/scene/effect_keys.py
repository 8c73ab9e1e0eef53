"""The scene's drive and load keys: the driving moments (`machine.drive`) and the resisting moments and forces on
the crank, on a mechanism's output and on a driven part (`machine.loads`, `driven.loads`, `branches[].loads`);
scene/schema.py describes the format and its sign conventions."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, model_validator

from mech_regulator.scene.key_types import NonNegative, Positive, SceneModel, check_table

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
    period_deg: Positive = Field(
        360.0, description="period of the table in crank angle (720 for a four-stroke cycle) [deg]"
    )

    @model_validator(mode="after")
    def _table(self) -> _TorqueTable:
        check_table(self.angle_deg, self.torque, self.period_deg, "torque table")
        return self


class TableDrive(_TorqueTable):
    """Periodic table of the driving moment over the crank angle, linear between points."""

    type: Literal["table"]


class Engine(SceneModel):
    """Gas force of an engine cylinder acting on the slider of a crank–slider: F_x = -p(angle) * area."""

    type: Literal["engine"]
    bore: Positive = Field(description="cylinder bore; the piston area is pi bore^2 / 4 [m]")
    angle_deg: list[float] = Field(
        min_length=2,
        description="cycle angles of the indicator-diagram points, 0 = a top dead centre at the start of intake [deg]",
    )
    pressure: list[float] = Field(min_length=2, description="gauge gas pressure at each cycle angle [Pa]")
    cycle_deg: Literal[360.0, 720.0] = Field(  # type: ignore[valid-type]  # pydantic takes a float Literal, typing not
        720.0, description="length of the working cycle: 720 four-stroke, 360 two-stroke [deg]"
    )
    phase_deg: float = Field(0.0, description="cycle angle (of cylinder 1) at crank angle phi = 0 [deg]")
    firing_order: list[int] | None = Field(
        None,
        description="multi-cylinder engine: the order in which the cylinders "
        "fire, e.g. [1, 3, 4, 2]; each fires at its first top "
        "dead centre after the previous one [-]",
    )
    firing_deg: list[float] | None = Field(
        None,
        description="multi-cylinder engine, instead of firing_order: each "
        "cylinder's firing delay after cylinder 1, the first 0; "
        "its cycle angle is cylinder 1's at phi - delay [deg]",
    )

    @model_validator(mode="after")
    def _table(self) -> Engine:
        check_table(self.angle_deg, self.pressure, self.cycle_deg, "engine pressure")
        if self.firing_order is not None and self.firing_deg is not None:
            raise ValueError("give either firing_order or firing_deg, not both")
        return self


Drive = Annotated[ConstantDrive | LinearMotor | TableDrive | Engine, Field(discriminator="type")]


# --------------------------------------------------------------------------------------------
# Loads


class ConstantLoad(SceneModel):
    type: Literal["constant"]
    torque: NonNegative = Field(
        description="resisting moment M_c, acting against the working direction: moment = -torque [N m]"
    )


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
    """On-off technological load (the lathe of docs/theory.md §3.6): -torque inside the intervals, 0 outside."""

    type: Literal["cutting"]
    torque: NonNegative = Field(description="resisting moment while cutting, F r [N m]")
    intervals_deg: list[list[float]] = Field(
        min_length=1, description="crank-angle intervals [start, end) in which the tool cuts, within one period [deg]"
    )
    period_deg: Positive = Field(360.0, description="period of the cutting pattern [deg]")

    @model_validator(mode="after")
    def _intervals(self) -> CuttingLoad:
        flat = []
        for interval in self.intervals_deg:
            if len(interval) != 2 or interval[1] <= interval[0]:
                raise ValueError(f"intervals_deg entry {interval} must be [start, end] with end > start")
            flat += interval
        if any(b < a for a, b in zip(flat, flat[1:])) or flat[-1] - flat[0] > self.period_deg:
            raise ValueError(
                f"intervals_deg = {self.intervals_deg} must be sorted, not overlap, and lie within "
                f"one period ({self.period_deg} deg)"
            )
        return self


class SliderConstant(SceneModel):
    type: Literal["slider_constant", "shuttle_constant"]
    force: float = Field(
        description="constant force along +x on the slider, or on the shuttle bar of a walking beam, signed [N]"
    )


class RockerConstant(SceneModel):
    type: Literal["rocker_constant"]
    torque: float = Field(description="constant moment on the rocker, counter-clockwise positive, signed [N m]")


class OutputViscous(SceneModel):
    type: Literal["slider_viscous", "rocker_viscous", "shuttle_viscous"]
    coefficient: NonNegative = Field(
        description="viscous coefficient on the slider, -c v [N s/m], on the rocker, "
        "-c omega_rocker [N m s/rad], or on the shuttle bar's horizontal "
        "motion, -c v_x [N s/m]"
    )


class OutputSpring(SceneModel):
    type: Literal["slider_spring", "rocker_spring", "shuttle_spring"]
    stiffness: NonNegative = Field(
        description="spring stiffness on the slider, -k (x - x0) [N/m], on the rocker, "
        "-k (theta4 - theta0) [N m/rad], or on the shuttle bar, horizontal, "
        "-k (x_C - x0) [N/m]"
    )
    free_position: float = Field(
        0.0, description="free slider (or shuttle point C) position x0 [m], or free rocker angle theta0 [rad]"
    )


class SliderTable(SceneModel):
    """Force on the slider tabulated over its position, linear between points, constant beyond the ends."""

    type: Literal["slider_table"]
    position: list[float] = Field(min_length=2, description="slider positions x, strictly increasing [m]")
    force: list[float] = Field(min_length=2, description="signed force along +x at each position [N]")

    @model_validator(mode="after")
    def _table(self) -> SliderTable:
        if len(self.position) != len(self.force):
            raise ValueError(
                f"slider_table: {len(self.position)} positions but {len(self.force)} forces; "
                "expected one force per position"
            )
        if any(b <= a for a, b in zip(self.position, self.position[1:])):
            raise ValueError(f"slider_table: position = {self.position} must be strictly increasing")
        return self


Load = Annotated[
    ConstantLoad
    | ViscousLoad
    | FanLoad
    | TableLoad
    | CuttingLoad
    | SliderConstant
    | RockerConstant
    | OutputViscous
    | OutputSpring
    | SliderTable,
    Field(discriminator="type"),
]


DrivenLoad = Annotated[
    ConstantLoad
    | ViscousLoad
    | FanLoad
    | TableLoad
    | SliderConstant
    | RockerConstant
    | OutputViscous
    | OutputSpring
    | SliderTable,
    Field(discriminator="type"),
]
BranchLoad = Annotated[ConstantLoad | ViscousLoad | FanLoad, Field(discriminator="type")]
