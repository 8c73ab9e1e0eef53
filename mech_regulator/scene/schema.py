"""The scene format: one YAML file describing a machine, what acts on it, the scenario and the solver.

The pydantic models are the single source of truth for the format: validation, the JSON Schema
(`mech-regulator schema`) and the key tables of `docs/scenes.md` all come from them. This module holds the root,
`Scene`, and the checks across its sections; each section family has its module beside it: mechanism_keys (the
mechanisms and linkages), effect_keys (drives and loads), machine_keys (the machine put together, its driven parts
and joint friction), governor_keys (governors and valves), scenario_keys (scenario, solver and analysis), on the
shared base of key_types. Every field's description states its unit (SI unless the key name says `_deg`).

Conventions: the crank angle phi is measured counter-clockwise from the +x axis, the crank pin is
at `B = (R cos phi, R sin phi)`; positive moments turn the crank counter-clockwise (the working
direction); load values are resisting magnitudes unless a description says "signed".
"""

from __future__ import annotations

from pydantic import Field, model_validator

from mech_regulator.scene.governor_keys import Governor
from mech_regulator.scene.key_types import SceneModel
from mech_regulator.scene.machine_keys import Machine
from mech_regulator.scene.scenario_keys import Analysis, Scenario, Solver


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
        if self.machine.coupling is None and self.machine.clutch is None and initial.omega_driven is not None:
            raise ValueError(
                "scenario.initial.omega_driven is set but the machine has no driven part (no coupling and no clutch)"
            )
        if self.machine.clutch is not None and self.solver.method == "energy":
            raise ValueError(
                "solver.method 'energy' steps one crank angle; a machine with a clutch has two masses: "
                "use a method in time (DOP853, RK45, RK23, Radau, BDF, LSODA or RK4)"
            )
        if self.machine.coupling is not None and self.solver.method == "energy":
            raise ValueError(
                "solver.method 'energy' steps one crank angle; a machine with a coupling has two "
                "masses: use a method in time (Radau or BDF for a stiff coupling, else DOP853)"
            )
        if self.governor is None:
            for key in ("sleeve", "servo"):
                if getattr(initial, key) is not None:
                    raise ValueError(f"scenario.initial.{key} is set but the scene has no governor")
            return self
        if self.machine.drive is None:
            raise ValueError("the governor scales the driving moment, but machine.drive is missing")
        if self.solver.method == "energy":
            raise ValueError(
                "solver.method 'energy' integrates the machine alone in phi; a governed scene needs a "
                "method in time (DOP853, RK45, RK23, Radau, BDF, LSODA or RK4)"
            )
        if self.governor.type == "pi":
            for key in ("sleeve", "servo"):
                if getattr(initial, key) is not None:
                    raise ValueError(
                        f"scenario.initial.{key} is set but the governor is 'pi' (it has no sleeve and "
                        "no servo-motor: the integral part starts where the throttle balances the load)"
                    )
            return self
        low, high = self.governor.stroke
        if initial.sleeve is not None and not low <= initial.sleeve <= high:
            raise ValueError(
                f"scenario.initial.sleeve = {initial.sleeve} m lies outside the governor's stroke "
                f"{self.governor.stroke} m"
            )
        if initial.servo is not None:
            if self.governor.type != "indirect":
                raise ValueError(
                    f"scenario.initial.servo is set but the governor is '{self.governor.type}' (it has no servo-motor)"
                )
            low, high = self.governor.servo.travel
            if not low <= initial.servo <= high:
                raise ValueError(
                    f"scenario.initial.servo = {initial.servo} lies outside the servo travel "
                    f"{self.governor.servo.travel}"
                )
        return self
