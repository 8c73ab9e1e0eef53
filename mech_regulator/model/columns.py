"""What a machine model records of a run: the output columns at sample times (speeds, moments by effect, energy,
the output link's motion, the governor's and the drive train's signals, the joints' friction) and the moments on the
crank by source (docs/theory.md §2.3). MachineModel (model/machine.py) has the columns method."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from mech_regulator.model.drivetrain import CLUTCH_CODE, DIRECTION
from mech_regulator.scene.mechanism_keys import Linkage

if TYPE_CHECKING:
    from mech_regulator.model.machine import MachineModel


class MachineColumns:
    """MachineModel's output columns, mixed into it. The method's self is the MachineModel (its fields and
    right-hand side): mypy checks it against it but refuses a self type narrower than this class, hence the
    `type: ignore[misc]` on its first line."""

    def columns(  # type: ignore[misc]
        self: MachineModel,
        t: np.ndarray,
        y: np.ndarray,
        throttle: np.ndarray | None = None,
        external: np.ndarray | None = None,
    ) -> dict[str, np.ndarray]:
        """Output columns at sample times t [s] for states y (shape n_states x n). throttle [-] and external
        [N m] (the load's magnitude): inputs given from outside the model (co-simulation) at each sample,
        in place of the governor's throttle and the scenario's load.

        t, phi, omega, epsilon, J, dJ_dphi, M_drive (as applied, throttle included), M_load (sum of
        all resisting moments and the external load), one M_<effect> column per load (and M_weight,
        M_external when present), E_kinetic = 1/2 J omega^2, the output coordinate with its speed
        (x, v for a slider, theta4, omega4 for a rocker, x_shuttle [m], v_shuttle [m/s] for a walking beam's
        shuttle bar; with several cylinders x_slider, v_slider are piston 1's and x_slider_k, v_slider_k piston k's)
        and, governed: throttle, sleeve z [m], sleeve_velocity z' [m/s], arm_angle [rad], servo [-] and
        feedback_shift [m] where present.
        With a coupling: M_coupling = -M_m (the coupling's moment on the crank, part of M_load; the external
        load is not), twist [rad], phi_driven = phi - twist [rad], omega_driven [rad/s], I2 [kg m^2] and
        dI2_dphi2 [kg m^2/rad] (the driven part's inertia), M_driven_<effect>, M_driven_weight (with a driven
        mechanism and gravity) and M_driven_external (moments on the driven part [N m]), its mechanism's output
        (x_driven, v_driven or theta4_driven, omega4_driven), E_elastic = integral_0^twist M_elastic dtwist
        [J]; E_kinetic includes 1/2 I2 omega_driven^2.
        With joint friction: M_joint_friction (part of M_load), friction_<joint> and reaction_<joint>
        (_joint_friction_columns); epsilon then solves the implicit equation of effects.joint_friction.
        With a clutch: clutch_torque (the moment it passes to the driven part; M_load includes minus it) [N m],
        slip_speed = omega - omega_driven [rad/s], clutch_mode (0 stuck, +1 slipping with the motor ahead, -1
        with the machine ahead), omega_driven, M_driven_<effect>, M_driven_external, E_kinetic as above. Either
        driven part adds epsilon_driven [rad/s^2], driven_mode (+1 turning forward, -1 backward, 0 held at rest
        by its resistances), its loads reduced to its shaft as M_driven_<effect> (a branch's as
        M_driven_<branch>_<effect>; Coulomb ones as mobilised) and the torque in each branch's section
        M_section_<branch> = M_n,c + (I_n / i_1n) epsilon_driven on the branch's shaft [N m].
        """
        n = t.size
        names = [effect.name for effect in self.effects]
        per_effect = np.zeros((len(names), n))
        J = np.full(n, self.inertia_constant)
        dJ = np.zeros(n)
        weight = np.zeros(n)
        cylinders = getattr(self.scene.machine.mechanism, "cylinders", None)
        q = np.zeros((n, len(cylinders)) if cylinders else n)  # several cylinders: one column per piston
        dq = np.zeros_like(q)
        given = external is not None
        external = np.array([self.external_load(ti) for ti in t]) if external is None else np.asarray(external)
        outside_throttle = throttle is not None
        throttle = np.ones(n) if throttle is None else np.array(throttle, dtype=float)
        for i in range(n):
            phi, omega = y[0, i], y[1, i]
            if self.reduced is not None:
                J_links, dJ[i], weight[i], q[i], dq[i] = self.reduced(phi)
                J[i] += J_links
            for k, effect in enumerate(self.effects):
                per_effect[k, i] = effect.moment(t[i], phi, omega, q[i], dq[i])
            if self.governor is not None and not outside_throttle:
                throttle[i] = self.governor.throttle(y[:, i])
        omega = y[1]
        drive = throttle * sum((per_effect[k] for k, e in enumerate(self.effects) if e.role == "drive"), np.zeros(n))
        load = sum((per_effect[k] for k, e in enumerate(self.effects) if e.role == "load"), np.zeros(n))
        coupling = self.coupling
        driven = self.driven
        if driven is not None:
            train = [self.drive_train_at(ti, y[:, i], external[i]) for i, ti in enumerate(t)]
            forces = {
                key: np.array([getattr(state[1], key) for state in train]) for key in ("driven", "clutch", "factor")
            }
            omega_driven = y[self.driven_speed_index]
        if driven is None:
            load = load - external
        elif coupling is not None:
            twist = y[self.coupling_index]
            passed = coupling.moment(twist, y[1] - omega_driven)
            load = load - passed
        else:
            load = load - forces["clutch"]
        net = drive + load + weight
        if self.joint_friction is not None:
            friction_columns = self._joint_friction_columns(t, y, J, net - 0.5 * dJ * omega**2, q, dq, throttle)
            load = load + friction_columns["M_joint_friction"]
            net = net + friction_columns["M_joint_friction"]
        out = {
            "t": t,
            "phi": y[0],
            "omega": omega,
            "epsilon": (net - 0.5 * dJ * omega**2) / J,
            "J": J,
            "dJ_dphi": dJ,
            "M_drive": drive,
            "M_load": load,
        }
        for k, name in enumerate(names):
            if self.effects[k].role == "load":
                out[f"M_{name}"] = per_effect[k]
        if self.has_weight:
            out["M_weight"] = weight
        if self.joint_friction is not None:
            out.update(friction_columns)
        if coupling is not None:
            out["M_coupling"] = -passed
        if self.clutch is not None:
            out["clutch_torque"] = forces["clutch"]
            out["slip_speed"] = omega - omega_driven
            out["clutch_mode"] = np.array([CLUTCH_CODE[state[0][0]] for state in train])
        if driven is not None:
            phi_driven = y[0] - twist if coupling is not None else np.zeros(n)
            state = np.array([driven.state(p) for p in phi_driven]).T.reshape(5, n)
            for effect, dry in zip(driven.effects, driven.coulomb):
                moment = np.array(
                    [
                        effect.moment(ti, p, w, q2, dq2)
                        for ti, p, w, q2, dq2 in zip(t, phi_driven, omega_driven, state[3], state[4])
                    ]
                )
                out[f"M_driven_{effect.name}"] = moment * forces["factor"] if dry else moment
            if driven.has_weight:
                out["M_driven_weight"] = state[2]
            out["M_driven_external"] = -external * forces["factor"]
            if coupling is not None:
                out["twist"], out["phi_driven"] = twist, phi_driven
                out["I2"], out["dI2_dphi2"] = state[0], state[1]
                assert self.scene.machine.coupling is not None, "the model's coupling is the scene's"
                driven_mechanism = self.scene.machine.coupling.driven.mechanism
                if driven_mechanism is not None:
                    slider = (
                        driven_mechanism.type == "crank_slider"
                        or getattr(driven_mechanism, "output_kind", None) == "slider"
                    )
                    position, speed = ("x_driven", "v_driven") if slider else ("theta4_driven", "omega4_driven")
                    out[position], out[speed] = state[3], state[4] * omega_driven
            out["omega_driven"] = omega_driven
            out["epsilon_driven"] = forces["driven"]
            out["driven_mode"] = np.array([DIRECTION[state[0][-1]] for state in train])
            for branch in driven.branches:
                resisting = -branch.ratio * sum(out[f"M_driven_{driven.effects[i].name}"] for i in branch.effects)
                out[f"M_section_{branch.name}"] = resisting + branch.inertia / branch.ratio * forces["driven"]
            out["E_kinetic"] = 0.5 * J * omega**2 + 0.5 * state[0] * omega_driven**2
            if coupling is not None:
                out["E_elastic"] = coupling.elastic_energy(twist)
        else:
            if self.load_pieces or given:
                out["M_external"] = -external
            out["E_kinetic"] = 0.5 * J * omega**2
        mechanism = self.scene.machine.mechanism
        kind = mechanism.type if mechanism is not None else None
        if kind == "crank_slider" and cylinders:
            out["x_slider"], out["v_slider"] = q[:, 0], dq[:, 0] * omega  # piston 1
            for k in range(1, len(cylinders)):
                out[f"x_slider_{k + 1}"], out[f"v_slider_{k + 1}"] = q[:, k], dq[:, k] * omega
        elif kind == "crank_slider":
            out["x_slider"], out["v_slider"] = q, dq * omega
        elif kind == "four_bar":
            out["theta4"], out["omega4"] = q, dq * omega
        elif kind == "walking_beam":
            out["x_shuttle"], out["v_shuttle"] = q, dq * omega
        elif isinstance(mechanism, Linkage) and mechanism.output is not None:  # its output: a travel or an angle
            position, speed = ("x_output", "v_output") if mechanism.output.joint else ("theta_output", "omega_output")
            out[position], out[speed] = q, dq * omega
        if self.governor is not None:
            out["throttle"] = throttle
            out.update(self.governor.signals(y))
        return out


def crank_moments(columns: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The moments on the crank by source from MachineModel.columns [N m]: drive (throttle included),
    resistance (the machine's own loads and the links' weight), external (minus the external load) and
    net = M_d + M_c = J epsilon + 1/2 J' omega^2 (docs/theory.md §2.3)."""
    external = columns.get("M_external", np.zeros_like(columns["omega"]))
    return {
        "drive": columns["M_drive"],
        "resistance": columns["M_load"] - external + columns.get("M_weight", 0.0),
        "external": external,
        "net": columns["J"] * columns["epsilon"] + 0.5 * columns["dJ_dphi"] * columns["omega"] ** 2,
    }
