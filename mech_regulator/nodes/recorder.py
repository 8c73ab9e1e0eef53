"""recorder_node: records a run from the topics into a Rerun recording (a .rrd file and/or a live
viewer) with its blueprint, and at the end writes the run's samples (CSV) and summary (JSON).

Subscribes `machine/moments` (the machine's states and moments, several exchanges a message: only the governor and
outside clients need `joint_states` at every exchange), `governor/state`, `governor/events`, `machine/status` and
`/diagnostics`;
publishes its own `/diagnostics` every second: `recorded_exchanges` (complete exchanges so far) and
`recorded_until` [s].
The text log gets every change of the applied load, the governor's mode changes and the machine's
warnings (fail-safe, overspeed trip). When the machine says it finished (`machine/status`) the recorder
waits for the last samples, closes the recording and exits; on Ctrl-C it closes what it has, so the
recording stays valid. A new trial number in `machine/status` is a new trial (the machine's ~/reset):
the CSV and the summary are of the last trial, the recording keeps every trial with an event at each reset.
It takes the machine's topics from its machine only, the governor's from its governor, and reads on `/diagnostics`
the statuses of the machine, governor and scenario from those nodes only (docs/ros.md, "Who may speak"); the summary
adds what they and it refused (`refused`: topic -> reason -> count) and what disturbed the run (`disturbances`; status
`disturbed` when one may have changed its numbers).
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Mapping, Reversible
from pathlib import Path

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from mech_regulator.analysis import cosimulation_ending, summarise_cosimulation
from mech_regulator.cli.report.data import to_json, write_csv
from mech_regulator.nodes.common import (
    IDLE_SPIN_SLICE,
    MATCH_POLL,
    OK,
    STATE_QOS,
    OutputError,
    RunState,
    batch_groups,
    coupling_parameter,
    diagnostics,
    float_parameter,
    follow_run_state,
    peer_parameter,
    run,
    scene_model,
    spin_once,
    text_parameter,
)
from mech_regulator.nodes.controller import CONTROLLERS
from mech_regulator.nodes.outputs import default_recording, write_empty_run
from mech_regulator.nodes.trust import (
    BadMessage,
    GovernorEvent,
    Refusals,
    RunStateMessage,
    Speakers,
    about_the_nodes,
    bounded,
    json_message,
    merge_counts,
    real_number,
    receive,
    report_of,
)
from mech_regulator.scene import SceneError
from mech_regulator.solvers.cosim import CoSimulation, seconds
from mech_regulator.viz.bag import write_bag
from mech_regulator.viz.recording import RunRecording

FLUSH_PERIOD = 0.5  # [s] of wall time between writes to the recording
FINISH_GRACE = 10.0  # [s] of wall time the last samples get to arrive after the machine has finished
STREAMS_WAIT = 10.0  # [s] of wall time the recorder waits for its streams' publishers (subscribe_to_the_machine)
DIAGNOSTICS_PERIOD = 1.0  # [s] of wall time between the recorder's diagnostics
LEVELS = {DiagnosticStatus.WARN: "WARN", DiagnosticStatus.ERROR: "ERROR"}


class RecorderNode(Node):
    """Records the run (see the module docstring)."""

    def __init__(self):
        super().__init__("recorder")
        self.model = scene_model(self)
        output = text_parameter(
            self, "output", "", "the .rrd file to write ('' : runs/<scene>-<time>.rrd; 'none': no file)"
        )
        connect = text_parameter(
            self,
            "connect",
            "",
            "URL of a live Rerun viewer to stream to, e.g. rerun+http://127.0.0.1:9876/proxy ('' : none)",
        )
        rate = float_parameter(
            self,
            "animation_rate",
            200.0,
            "frames of the animation per second of simulation time [Hz]",
            1.0,
            1e5,
            read_only=True,
        )
        self.exchange_step = float_parameter(
            self,
            "exchange_step",
            self.model.scene.solver.exchange_step,
            "the machine's exchange step [s], for the summary (default: the scene's solver.exchange_step)",
            1e-6,
            1.0,
            read_only=True,
        )
        self.coupling = coupling_parameter(self)
        self.launched_at = float_parameter(
            self,
            "launched_at",
            0.0,
            "time.monotonic() [s] at which the command that "
            "started the run started (`run` sets it), for the start-up time in the "
            "summary; 0: not known",
            0.0,
            1e12,
            read_only=True,
        )
        self.controller = text_parameter(
            self,
            "controller",
            "governor",
            "what gives the throttle: the scene's "
            "governor, or external (its throttle is read from machine/moments and "
            "written to the CSV)",
            CONTROLLERS,
        )
        bag = text_parameter(self, "bag", "", "a rosbag2 folder to write the run to at the end (viz/bag.py; '': none)")
        self.bag = Path(bag) if bag else None
        self.max_lag: float | None = None  # realtime: the machine's largest lag [s] behind the wall clock
        self.path = None if output == "none" else Path(output) if output else default_recording(self.model.scene.name)
        if self.path is None and not connect:
            raise SceneError("recorder_node: output = 'none' and no connect URL: nothing to record to")
        if self.path is not None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        self.recording = RunRecording(
            self.model,
            path=self.path,
            connect=connect or None,
            animation_rate=rate,
            outside_throttle=self.controller == "external",
        )
        self.machine: dict[int, list[float]] = {}  # stamp -> the machine's state (phi, omega, then a two-mass
        # machine's twist and omega_driven or a clutch's omega_driven, as MachineModel.state_names)
        self.trial = 1
        self.machine_result = ("complete", "")  # the machine's solver status and its message
        self.moments: dict[int, tuple[float, float, float]] = {}  # stamp -> (drive, external load) [N m], throttle [-]
        self.governor: dict[int, dict[str, float]] = {}
        # the exchange times all parts are in for, and the newest: kept as the parts come (the streams' dicts are in
        # the order of their times), so that the report each second costs nothing however long the run
        self.completed: set[int] = set()
        self.completed_until: int | None = None
        self.events: list[tuple[float, str, tuple[str, str]]] = []
        self.machine_status = (DiagnosticStatus.OK, "")
        self.finished_at: int | None = None
        self.machine_reported_end = False  # its last diagnostics (with its refusals and disturbances) are in
        self.tripped_at: float | None = None  # [s], from the machine's diagnostics
        self.machine_exchanges: int | None = None  # the exchange times the machine published in its last trial,
        # from its last diagnostics (missed)
        self.closed = False
        self.write_failures: list[str] = []  # one line per output that could not be written (close)
        self.state_walls: list[float] = []  # wall-clock times [s] of the first and the latest machine state
        self.diagnostics_publisher = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.refusals = Refusals(self, self.report)
        self.speakers = Speakers(self)
        self.peer_names = {role: peer_parameter(self, role) for role in ("machine", "governor", "scenario")}
        for topic in ("machine/moments", "machine/status"):
            self.speakers.allow(topic, self.peer_names["machine"])
        for topic in ("governor/state", "governor/events"):
            self.speakers.allow(topic, self.peer_names["governor"])
        self.own_name = self.get_name()  # (for the summary, written after Ctrl-C may have shut rclpy down)
        self.speakers.allow("/diagnostics", self.own_name, *self.peer_names.values())
        self.reports: dict[str, tuple[dict, list[str], bool]] = {}  # peer node -> its refusals, disturbances and
        # whether they alter the results (trust.report_of), from its latest diagnostics
        governor_states = receive(
            self, JointState, "governor/state", self.on_governor, STATE_QOS, self.refusals, self.speakers
        )
        self.streams = [governor_states] if self.model.governor is not None else []
        receive(self, String, "governor/events", self.on_governor_event, STATE_QOS, self.refusals, self.speakers)
        receive(
            self,
            DiagnosticArray,
            "/diagnostics",
            self.on_diagnostics,
            50,
            self.refusals,
            self.speakers,
            pass_speaker=True,
            concerns=about_the_nodes,
        )
        follow_run_state(self, self.on_run_state, self.refusals, self.speakers)
        self.create_timer(FLUSH_PERIOD, self.recording.flush)
        self.create_timer(DIAGNOSTICS_PERIOD, self.report)
        self.get_logger().info(f"recording to {self.path if self.path is not None else connect}")

    def start_trial(self, trial: int) -> None:
        """The machine's ~/reset (trial: the new trial's number): forget the samples of the trial before (the
        recording keeps them)."""
        self.trial = trial
        for samples in (self.machine, self.moments, self.governor, self.completed):
            samples.clear()
        self.completed_until = None
        self.events.clear()
        self.state_walls.clear()
        self.recording.add_event(0, f"reset: trial {self.trial} starts from the initial state")

    def on_run_state(self, state: RunStateMessage) -> None:
        if state.trial > self.trial:
            self.start_trial(state.trial)
        self.machine_result = (state.status, self.machine_status[1])
        self.max_lag = state.max_lag_s if state.max_lag_s is not None else self.max_lag
        if state.state == RunState.FINISHED:
            self.finished_at = state.finished_at_ns
            self.tripped_at = state.tripped_at

    def on_moments(self, message: JointState) -> None:
        """The machine's states and moments of one or more exchange times (common.Batch), in order, after the last
        one recorded; every value read checked first (trust.BadMessage)."""
        needed = ["crank", "drive", "resistance", "external", "net", "load"]
        needed += ["coupling"] if self.model.coupling is not None else []
        needed += ["driven"] if self.model.driven is not None else []
        groups = unrecorded(batch_groups(message, tuple(needed)), self.machine, "machine/moments")
        for when, joints in groups:
            checks = [(joints["crank"][0], "crank position [rad]"), (joints["crank"][1], "crank velocity [rad/s]")]
            checks += [(joints[name][2], f"{name} effort [N m]") for name in needed[1:6]]
            checks += [(joints["coupling"][0], "coupling position [rad]")] if "coupling" in needed else []
            checks += [(joints["driven"][1], "driven velocity [rad/s]")] if "driven" in needed else []
            for value, what in checks:
                bounded(value, -math.inf, math.inf, f"machine/moments at {seconds(when):.9g} s: {what}")
        for when, joints in groups:
            phi, omega = joints["crank"][:2]
            driven = {}
            if self.model.coupling is not None:
                driven["twist"] = joints["coupling"][0]
            if self.model.driven is not None:
                driven["omega_driven"] = joints["driven"][1]
            self.machine[when] = [phi, omega, *driven.values()]
            self.state_walls[1:] = [joints["stamp"][1]]  # when the machine published that state
            self.recording.add_machine(when, phi, omega, driven or None)
            moments = {name: effort for name, (_, _, effort) in joints.items()}
            self.recording.add_moments(
                when, moments["drive"], moments["resistance"], moments["external"], moments["net"]
            )
            self.recording.add_external_load(when, moments["load"])  # a ramp becomes one event, a jump a step
            self.moments[when] = (moments["drive"], moments["load"], joints["throttle"][0])
            self.part_arrived(when)
            if self.controller == "external":
                self.recording.add_throttle(when, joints["throttle"][0])

    def on_governor(self, message: JointState) -> None:
        """The governor's state at one or more exchange times (common.Batch), in order, after the last one recorded;
        every value read checked first (trust.BadMessage)."""
        if self.model.governor is None:
            raise BadMessage("no governor", f"scene '{self.model.scene.name}' has no governor")
        shown = self.model.governor.joints()  # GovernorKind.joints: (joint, position's key, velocity's key or None)
        groups = unrecorded(batch_groups(message, tuple(name for name, _, _ in shown)), self.governor, "governor/state")
        for when, joints in groups:
            checked = [
                value
                for name, _, velocity in shown
                if name != "throttle"
                for value in (joints[name][:2] if velocity is not None else joints[name][:1])
            ]
            for value in checked:
                bounded(value, -math.inf, math.inf, f"governor/state at {seconds(when):.9g} s")
            bounded(joints["throttle"][0], 0.0, 1.0, f"governor/state at {seconds(when):.9g} s: throttle")
        for when, joints in groups:
            values = {position: joints[name][0] for name, position, _ in shown}
            values.update({velocity: joints[name][1] for name, _, velocity in shown if velocity is not None})
            self.governor[when] = values
            self.recording.add_governor(when, values)
            self.part_arrived(when)

    def on_governor_event(self, message: String) -> None:
        event = json_message(message.data, GovernorEvent)
        self.events.append((event.time, event.event, tuple(event.mode)))
        self.recording.add_mode_change(int(round(event.time * 1e9)), event.event)

    def on_diagnostics(self, message: DiagnosticArray, speaker: str) -> None:
        """The statuses of the machine, governor and scenario (each from that node: `speaker`; one that names another
        node is refused): their refusals and disturbances for the summary, and the machine's warnings and trip time.
        Every value read is checked before any is used (trust.BadMessage)."""
        own = f"mech_regulator: {self.get_namespace().rstrip('/')}/{speaker}"
        statuses = [status for status in message.status if status.name.startswith("mech_regulator: ")]
        strangers = [status.name for status in statuses if status.name != own]
        if strangers:
            raise BadMessage("names another node", f"diagnostics from '{speaker}' with statuses {strangers}")
        if speaker == self.own_name:
            return
        for status in statuses:
            values = {item.key: item.value for item in status.values}
            report = report_of(values)
            machine = speaker == self.peer_names["machine"]
            times = (  # the machine's, checked before anything is kept
                (
                    real_number(values.get("sim_time", "0"), "sim_time"),
                    real_number(values.get("tripped_at", "None"), "tripped_at", allow_none=True),
                    real_number(values.get("exchanges", "None"), "exchanges", allow_none=True),
                )
                if machine
                else None
            )
            self.reports[speaker] = report
            if times is None:
                continue
            when, tripped_at, exchanges = times
            if (status.level, status.message) != self.machine_status and status.level in LEVELS:
                self.recording.add_event(int(round(when * 1e9)), f"machine: {status.message}", LEVELS[status.level])
            self.machine_status = (status.level, status.message)
            if tripped_at is not None:
                self.tripped_at = tripped_at
            self.machine_reported_end = self.machine_reported_end or "finished_at_ns" in values
            if exchanges is not None:
                self.machine_exchanges = int(exchanges)

    def complete(self) -> bool:
        """Whether the machine finished and its last samples (and the governor's) and its last diagnostics are in."""
        if self.finished_at is None or self.finished_at not in self.machine or not self.machine_reported_end:
            return False
        return self.model.governor is None or self.finished_at in self.governor

    def close(self) -> None:
        """Finish the recording, then write the samples (CSV), the bag and the summary (JSON) next to it; stopped
        before a first complete exchange, the summary alone (status interrupted, samples 0). Each output is written
        on its own: one that cannot be written (a disk that filled up) is said in one line on stderr and kept in
        write_failures, and the others are still written; nothing here raises."""
        if self.closed:
            return
        self.closed = True
        run_data = self.run_data()
        status, message = "interrupted", "before the first complete exchange"
        if run_data is not None:
            status, message = (
                cosimulation_ending(run_data)
                if self.complete()
                else ("interrupted", f"the recording stops at t = {run_data.times[-1]:.6g} s")
            )
            if self.machine_result[0] not in ("complete", "interrupted"):  # the machine's own end (failed, ...)
                status, message = self.machine_result
            elif self.missed():
                status, message = (
                    "interrupted",
                    (
                        f"{self.missed()} of the {self.machine_exchanges} exchanges the machine published are "
                        "incomplete here (a part never came: a peer fell silent, or the recorder fell behind more "
                        'than the publishers keep, docs/speed.md, "The nodes\' side of an exchange")'
                    ),
                )
        self._write("recording", self.path, lambda: self.recording.close(status, message))
        if self.path is None:
            return
        summary_path = self.path.with_suffix(".json")
        if run_data is None:  # stopped before all parts of a first exchange were in: no samples, no CSV
            self._write(
                "summary",
                summary_path,
                lambda: write_empty_run(
                    self.model, self.path, self.exchange_step, extra=self.trust_summary("interrupted")
                ),
            )
            return
        summary = summarise_cosimulation(self.model, run_data, self.exchange_step, self.coupling)
        summary.update(self.pace())
        if not self.complete() or self.machine_result[0] not in ("complete", "interrupted") or self.missed():
            summary["status"], summary["message"] = status, message  # the recording's end, said the same way
        summary.update(self.trust_summary(summary["status"]))
        csv_path = self.path.with_suffix(".csv")
        columns = self.model.columns(run_data.times, run_data.states, run_data.throttle, run_data.external_load)
        if self.controller == "external":
            columns["throttle"] = run_data.throttle
        summary["recording"] = str(self.path)
        if self._write("CSV", csv_path, lambda: write_csv(csv_path, columns, digits=17)):
            summary["csv"] = str(csv_path)
        if self.bag is not None and self._write(
            "bag",
            self.bag,
            lambda: write_bag(
                self.bag,
                self.model,
                run_data.times,
                run_data.states,
                run_data.throttle,
                run_data.external_load,
                summary["status"],
                summary.get("message", ""),
            ),
        ):
            summary["bag"] = str(self.bag)
        if self.write_failures:
            summary["not_written"] = list(self.write_failures)
        self._write("summary", summary_path, lambda: summary_path.write_text(to_json(summary)))

    def _write(self, what: str, path: Path | None, write) -> bool:
        """write(); True when it wrote, else (an OSError: a full disk, a folder gone) one line on stderr and in
        write_failures, False."""
        try:
            write()
            return True
        except OSError as error:
            line = (
                f"writing the {what} '{path}' failed: {error.strerror or error}; what was computed is in the "
                "outputs that were written"
            )
            self.write_failures.append(line)
            print(f"mech_regulator: recorder_node: {line}", file=sys.stderr)
            return False

    def trust_summary(self, status: str) -> dict:
        """The summary's `refused` (topic -> reason -> count, summed over the nodes that refused) and `disturbances`
        ('<node>: <what>') when there are any; status `disturbed` (and the first such disturbance as its message) when
        one may have changed the numbers of a run that was otherwise complete."""
        reports = {
            **self.reports,
            self.own_name: (self.refusals.counts, self.refusals.disturbances, self.refusals.alters_results),
        }
        refused: dict[str, dict[str, int]] = {}
        disturbances: list[str] = []
        alters = False
        for node, (counts, texts, alters_results) in sorted(reports.items()):
            merge_counts(refused, counts)
            disturbances += [f"{node}: {text}" for text in texts]
            alters = alters or alters_results
        summary: dict = {}
        if refused:
            summary["refused"] = refused
        if disturbances:
            summary["disturbances"] = disturbances
        if alters and status == "complete":
            summary.update(
                status="disturbed",
                message="the run was disturbed, its numbers may not be the scene's: " + "; ".join(disturbances),
            )
        return summary

    def pace(self) -> dict[str, float]:
        """How fast the nodes ran, from the wall-clock times the machine published its first and its last state
        (the "stamp" joints' velocity in machine/moments, time.monotonic of this host; the exchanges only: the nodes'
        start-up and discovery before the first exchange are not in it): wall_time_s [s] and real_time_factor =
        simulated time between those states / wall_time_s; empty before two states. Also start_up_s, the wall time
        [s] from the command's start (parameter launched_at) to the first machine state,
        and in realtime max_lag_s, the machine's largest lag [s] of simulation time behind the wall clock."""
        if len(self.state_walls) < 2 or self.state_walls[1] <= self.state_walls[0]:
            return {}
        wall = self.state_walls[1] - self.state_walls[0]
        pace = {
            "wall_time_s": wall,
            "real_time_factor": (seconds(max(self.machine)) - seconds(min(self.machine))) / wall,
        }
        if self.launched_at > 0.0 and self.trial == 1:
            pace["start_up_s"] = self.state_walls[0] - self.launched_at
        if self.max_lag is not None:
            pace["max_lag_s"] = self.max_lag
        return pace

    def received(self) -> str:
        """What came of each stream: how many exchange times and the last one [s], e.g. 'machine states: 301 up to
        0.3 s; machine moments: 0; governor states: 301 up to 0.3 s'."""
        streams: dict[str, Mapping[int, object]] = {"machine states": self.machine, "machine moments": self.moments}
        if self.model.governor is not None:
            streams["governor states"] = self.governor
        return "; ".join(
            f"{name}: {len(samples)}" + (f" up to {seconds(max(samples)):.6g} s" if samples else "")
            for name, samples in streams.items()
        )

    def part_arrived(self, when: int) -> None:
        """A part of the exchange at `when` [ns] came: the exchange is complete once the machine's state and
        moments and (with a governor) the governor's state are in."""
        if when in self.machine and when in self.moments and (self.model.governor is None or when in self.governor):
            self.completed.add(when)
            self.completed_until = when if self.completed_until is None else max(self.completed_until, when)

    def missed(self) -> int:
        """How many of the exchanges the machine said it published in the trial (its last diagnostics) are not
        complete here: a recorder stalled longer than the publishers' histories (common.HISTORY_DEPTH messages)
        misses the oldest; 0 while the machine has not said."""
        if self.machine_exchanges is None:
            return 0
        return max(self.machine_exchanges - len(self.completed), 0)

    def complete_times(self) -> list[int]:
        """The exchange times [ns] all parts (machine state, moments, governor state) were received for."""
        return sorted(
            when
            for when in self.machine
            if when in self.moments and (self.model.governor is None or when in self.governor)
        )

    def report(self) -> None:
        """Publish /diagnostics: how many complete exchanges are recorded and up to which time."""
        values = {
            "scene": self.model.scene.name,
            "recorded_exchanges": len(self.completed),
            "recorded_until": seconds(self.completed_until) if self.completed_until is not None else None,
        }
        level, text = self.refusals.status(OK, "recording")
        array = diagnostics(self, level, text, values)
        array.status[0].values += self.refusals.key_values()
        self.diagnostics_publisher.publish(array)

    def run_data(self) -> CoSimulation | None:
        """The run as the core's CoSimulation, from the exchange times all parts were received for."""
        times = self.complete_times()
        if not times:
            return None
        rows = []
        for when in times:
            machine = self.machine[when]
            row = machine[:2]
            if self.model.governor is not None:
                values = self.governor[when]  # its values are named as its states
                row += [values[name] for name in self.model.governor.state_names]
            rows.append(row + machine[2:])
        tripped = self.tripped_at if self.tripped_at is not None else np.inf
        throttle = [
            self.moments[when][2]
            if self.controller == "external"
            else 0.0
            if seconds(when) >= tripped
            else self.governor[when]["throttle"]
            if self.model.governor is not None
            else 1.0
            for when in times
        ]
        return CoSimulation(
            times=np.array([seconds(when) for when in times]),
            states=np.array(rows).T,
            throttle=np.array(throttle),
            external_load=np.array([self.moments[w][1] for w in times]),
            events=self.events,
            status="complete",
            message="",
            tripped_at=self.tripped_at,
        )

    def subscribe_to_the_machine(self) -> None:
        """Subscribe to the machine's states and moments (machine/moments) once the other stream the run needs (a
        governor's state) has matched its publisher, or after STREAMS_WAIT s: the machine starts as soon as its peers
        subscribe (the recorder: to machine/moments), and a short run could otherwise end before a stream has matched
        the recorder, its samples lost with the node that sent them."""
        waited = time.monotonic()
        while (
            rclpy.ok()
            and any(stream.get_publisher_count() == 0 for stream in self.streams)
            and time.monotonic() - waited < STREAMS_WAIT
        ):
            spin_once(self, MATCH_POLL)
        receive(self, JointState, "machine/moments", self.on_moments, STATE_QOS, self.refusals, self.speakers)

    def record(self) -> None:
        """Subscribe to the machine (subscribe_to_the_machine), then spin until the machine has finished and
        everything is in (or Ctrl-C); should the last samples not come within FINISH_GRACE s of the machine's end,
        close with what there is (the summary says where it stops)."""
        self.subscribe_to_the_machine()
        finished_seen = None
        while rclpy.ok() and not self.complete():
            spin_once(self, IDLE_SPIN_SLICE)
            if self.finished_at is not None:
                finished_seen = finished_seen or time.monotonic()
                if time.monotonic() - finished_seen > FINISH_GRACE:
                    self.get_logger().warning(
                        f"the machine finished at t = {seconds(self.finished_at):.6g} s but "
                        f"its last samples did not come within {FINISH_GRACE:g} s: closing "
                        f"with what was received ({self.received()})"
                    )
                    break
        self.close()
        if self.write_failures:  # said one by one already; the node ends with exit code 1
            raise OutputError(f"{len(self.write_failures)} output(s) could not be written: {self.write_failures[-1]}")


def unrecorded(groups: list[tuple[int, dict]], recorded: Reversible[int], topic: str) -> list[tuple[int, dict]]:
    """The groups of a batch (common.batch_groups) at exchange times not in `recorded` (a stream's samples by time
    [ns], in the order of their times), each time once: the machine publishes an exchange time again when no answer
    came within machine.RESEND_PERIOD (a loaded machine), and its governor then answers that time twice, the repeat in the
    same batch or opening the next; the first answer is the one recorded. A batch from before the newest time
    recorded is refused (trust.BadMessage)."""
    newest = next(reversed(recorded), None)  # (the dict's order is its times')
    if groups and newest is not None and groups[0][0] < newest:
        raise BadMessage("out of order", f"{topic} from {seconds(groups[0][0]):.9g} s after {seconds(newest):.9g} s")
    fresh: list[tuple[int, dict]] = []
    for when, joints in groups:
        if when != newest and (not fresh or when != fresh[-1][0]):
            fresh.append((when, joints))
    return fresh


def main() -> int:
    """Entry point of recorder_node."""
    return run(RecorderNode, RecorderNode.record)


if __name__ == "__main__":
    sys.exit(main())
