"""The scene's `scenario`, `solver` and `analysis` keys: the initial state, the duration and the load events; the
integration method, its accuracy and the exchange step; the settings of the post-run analysis."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from mech_regulator.scene.key_types import NonNegative, Positive, SceneModel

# --------------------------------------------------------------------------------------------
# Scenario and solver


class InitialState(SceneModel):
    phi: float = Field(0.0, description="initial crank angle [rad]")
    omega: float = Field(0.0, description="initial crank speed [rad/s]")
    sleeve: float | None = Field(
        None,
        description="initial governor sleeve position z, at rest; none = the "
        "equilibrium position at the initial speed [m]",
    )
    servo: float | None = Field(
        None,
        description="initial servo-motor position (throttle, indirect governor); none = "
        "the throttle that balances the initial load at the initial speed [-]",
    )
    twist: float | None = Field(
        None,
        description="initial twist phi - phi_driven of the coupling, driven part turning "
        "at omega; none = the static twist that carries the driven part's "
        "loads at the initial speed [rad]",
    )
    omega_driven: float | None = Field(
        None, description="initial speed of the driven part (behind a coupling or a clutch); none = omega [rad/s]"
    )


class LoadEvent(SceneModel):
    """A change of the external load moment (opposing motion) at a time, as a step or a linear ramp."""

    time: NonNegative = Field(description="time at which the change starts [s]")
    torque: float = Field(description="new external load moment reached at time + ramp; moment = -torque [N m]")
    ramp: NonNegative = Field(0.0, description="duration of a linear ramp to the new value; 0 = step [s]")


class Scenario(SceneModel):
    initial: InitialState = Field(default_factory=InitialState, description="initial state of the crank")
    duration: Positive = Field(description="simulated time [s]")
    external_load: float = Field(
        0.0, description="external load moment at t = 0, opposing motion: moment = -value [N m]"
    )
    load_events: list[LoadEvent] = Field(default_factory=list, description="changes of the external load in time")

    @model_validator(mode="after")
    def _events_in_order(self) -> Scenario:
        end_previous = 0.0
        for index, event in enumerate(self.load_events):
            if event.time < end_previous:
                raise ValueError(
                    f"load_events[{index}].time = {event.time} s starts before the previous change ends "
                    f"({end_previous} s); expected events in time order that do not overlap"
                )
            end_previous = event.time + event.ramp
            if end_previous > self.duration:
                raise ValueError(
                    f"load_events[{index}] ends at {end_previous} s, after the scenario's duration {self.duration} s"
                )
        return self


DEFAULT_EXCHANGE_STEP = 0.02  # [s] run's exchange step unless a scene sets solver.exchange_step (docs/ros.md, "Speed")


class Solver(SceneModel):
    method: Literal["RK45", "RK23", "DOP853", "Radau", "BDF", "LSODA", "RK4", "Rosenbrock23", "energy"] = Field(
        "DOP853",
        description="scipy.integrate method (adaptive, in time), RK4 (fixed step in time), Rosenbrock23 (the "
        "stiff method of the fast path only) or energy (the textbook energy method, fixed step "
        "in phi)",
    )
    path: Literal["auto", "reference", "fast"] = Field(
        "auto",
        description="auto: a command (simulate, sweep, flywheel, run, the nodes) runs the fast path where it "
        "covers the scene and is compiled on this machine, else the reference path with a "
        "one-line note (a first run starts compiling it in the background; run compiles it "
        "first); the library's "
        "simulate() runs auto on the reference path. reference: the pure-Python right-hand side "
        "stepped by scipy; fast: the scene's right-hand side compiled by numba (cached on disk) "
        "and stepped by compiled RK45, DOP853, RK4 or Rosenbrock23 (docs/speed.md); a command "
        "compiles its stepper first when it is not compiled yet, announced with its estimate (a "
        "method the fast path lacks runs on the reference path, with a note); the summary names "
        "the path that ran",
    )
    rtol: Positive = Field(1e-8, description="relative tolerance of the adaptive methods [-]")
    atol: Positive = Field(
        1e-10, description="absolute tolerance of the adaptive methods, on phi [rad] and omega [rad/s]"
    )
    max_step: Positive | None = Field(None, description="largest step of the adaptive methods; none = unlimited [s]")
    step: Positive = Field(1e-4, description="time step of RK4 [s]")
    phi_step_deg: Positive = Field(1.0, description="crank-angle step of the energy method [deg]")
    sample_rate: Positive = Field(1000.0, description="rate of the output samples (dense output) [Hz]")
    exchange_step: float = Field(
        DEFAULT_EXCHANGE_STEP,
        ge=1e-6,
        le=1.0,
        description=(
            "simulation time between the exchanges of the lockstep co-simulation (`run`, the ROS nodes), unless "
            "--exchange-step says otherwise: its error falls with it, its speed grows with it (docs/ros.md) [s]"
        ),
    )

    @model_validator(mode="after")
    def _method_on_path(self) -> Solver:
        if self.method == "Rosenbrock23" and self.path == "reference":
            raise ValueError(
                "solver.method 'Rosenbrock23' runs only on the compiled fast path; expected solver.path: "
                "fast, or a method of the reference path (RK45, RK23, DOP853, Radau, BDF, LSODA, RK4, "
                "energy)"
            )
        return self


class Analysis(SceneModel):
    steady_tolerance: Positive = Field(
        1e-4,
        description="steady when omega at the start of successive dynamic periods "
        "differs by less than this fraction of omega_m [-]",
    )
    settling_band: Positive = Field(
        0.002,
        description="a load change has settled once the cycle-mean speed stays "
        "within this fraction of the new steady speed [-]",
    )
    permitted_delta: Positive | None = Field(
        None,
        description="coefficient of speed fluctuation "
        "(omega_max - omega_min) / omega_m that the machine's class "
        "permits [-], e.g. 0.0125 (1/80) for an engine driving a "
        "generator; recordings draw the band omega_set (1 +- "
        "delta / 2) around the set speed",
    )
