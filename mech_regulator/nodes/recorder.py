"""recorder_node: records a run from the topics into a Rerun recording (a .rrd file and/or a live
viewer) with its blueprint, and at the end writes the run's samples (CSV) and summary (JSON).

Subscribes `machine/moments` (the machine's states and moments, several exchanges a message: only the governor and
outside clients need `joint_states` at every exchange), `governor/state`, `governor/events`, `machine/status` and
`/diagnostics`;
publishes its own `/diagnostics` every second: `recorded_exchanges` (complete exchanges so far) and
`recorded_until` [s].
The text log gets every change of the applied load, the governor's mode changes and the machine's
warnings (fail-safe, overspeed trip). When the machine says it finished (`machine/status`) the recorder
waits for the last samples (after a failed run only for those that can still come: the governor does not answer a
state it refuses), closes the recording and exits; on Ctrl-C it closes what it has, so the
recording stays valid. A new trial number in `machine/status` is a new trial (the machine's ~/reset):
the CSV and the summary are of the last trial, the recording keeps every trial with an event at each reset.
It takes the machine's topics from its machine only, the governor's from its governor, and reads on `/diagnostics`
the statuses of the machine, governor and scenario from those nodes only, refusing (and counting) every other
publisher's (docs/ros.md, "Who may speak"); the summary adds what they and it refused (`refused`: topic -> reason ->
count; `foreign`: sender -> topic -> count of those refused for who sent them) and what disturbed the run
(`disturbances`; status `disturbed` when one may have changed its numbers).
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from sensor_msgs.msg import JointState
from std_msgs.msg import Header, String

from mech_regulator.analysis import cosimulation_ending, summarise_cosimulation
from mech_regulator.cli.report.data import to_json
from mech_regulator.nodes.common import (
    IDLE_SPIN_SLICE,
    MATCH_POLL,
    OK,
    PARTICIPANT_LEASE,
    PROGRESS_QOS,
    RECORD_QOS,
    STATE_QOS,
    BatchColumns,
    OutputError,
    RunState,
    SteadyNode,
    batch_columns,
    coupling_parameter,
    diagnostics,
    exchange_tolerance_parameter,
    float_parameter,
    follow_run_state,
    peer_parameter,
    run,
    scene_model,
    spin_once,
    stamp,
    take_waiting,
    text_parameter,
)
from mech_regulator.nodes.controller import CONTROLLERS
from mech_regulator.nodes.outputs import default_recording, write_empty_run
from mech_regulator.nodes.run_rows import GOVERNOR, MACHINE, RunRows
from mech_regulator.nodes.trust import (
    BadMessage,
    GovernorEvent,
    Refusals,
    Report,
    RunStateMessage,
    Speakers,
    bounded_rows,
    json_message,
    merge_counts,
    real_number,
    receive,
    report_of,
)
from mech_regulator.scene import SceneError
from mech_regulator.solvers.cosim import seconds
from mech_regulator.viz.bag import write_bag
from mech_regulator.viz.recording import RunRecording

FLUSH_PERIOD = 0.5  # [s] of wall time between writes to the CSV, and to the recording with a live viewer
RECORDING_CHUNK = 5000  # exchanges gathered before they go to a recording file alone (no live viewer): Rerun keeps
# an entry of about 1.5 kB per chunk it wrote (a series' samples of one send) for the file's footer until the end,
# so that sends of 0.5 s would cost ~70 MB an hour of wall time; 5000 exchanges (100 s of engine_direct) ~1 MB an hour
FINISH_GRACE = 10.0  # [s] of wall time the last samples get to arrive after the machine has finished (or left without
# its end reaching the recorder), counted from the latest sample taken: a recorder still taking the samples it fell
# behind on is not cut short (a machine that failed: only those that can still come, RecorderNode.all_that_can_come)
HELD_BACK = 1.0  # [s] of wall time a wait for callbacks (IDLE_SPIN_SLICE) may take before the recorder counts its
# process as held back (stopped, starved): FINISH_GRACE then starts again
STREAMS_WAIT = 10.0  # [s] of wall time the recorder waits for its streams' publishers (subscribe_to_the_machine)
DIAGNOSTICS_PERIOD = 1.0  # [s] of wall time between the recorder's diagnostics
LEVELS = {DiagnosticStatus.WARN: "WARN", DiagnosticStatus.ERROR: "ERROR"}


class RecorderNode(SteadyNode):
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
        self.exchange_tolerance = exchange_tolerance_parameter(self)
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
        self.live = bool(connect)  # a live viewer: the recording is sent every FLUSH_PERIOD
        self.unsent = 0  # exchanges of the machine not yet sent to the recording
        self.recording = RunRecording(
            self.model,
            path=self.path,
            connect=connect or None,
            animation_rate=rate,
            outside_throttle=self.controller == "external",
        )
        self.write_failures: list[str] = []  # one line per output that could not be written (close, rows)
        self.rows = self.new_rows()  # the exchanges, written to the CSV as they complete (nodes/run_rows.py)
        self.untripped_until = -math.inf  # [s] the machine's time in its latest diagnostics that had not tripped
        self.trial = 1
        self.machine_result = ("complete", "")  # the machine's solver status and its message
        self.events: list[tuple[float, str, tuple[str, str]]] = []
        self.machine_status = (DiagnosticStatus.OK, "")
        self.finished_at: int | None = None
        self.machine_reported_end = False  # its last diagnostics (with its refusals and disturbances) are in
        self.tripped_at: float | None = None  # [s], from the machine's diagnostics
        self.machine_exchanges: int | None = None  # the exchange times the machine published in its last trial,
        # from its last diagnostics (missed)
        self.closed = False
        self.longest_hold = 0.0  # [s] of wall time the longest wait for callbacks took (its process stopped, starved)
        self.state_walls: list[float] = []  # wall-clock times [s] of the first and the latest machine state
        self.last_exchanges: list[int] = []  # [ns] the machine's two newest exchange times in the trial
        self.diagnostics_publisher = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.progress_publisher = self.create_publisher(Header, "recorder/progress", PROGRESS_QOS)
        self.refusals = Refusals(self, self.report)
        self.speakers = Speakers(self)
        self.peer_names = {role: peer_parameter(self, role) for role in ("machine", "governor", "scenario")}
        for topic in ("machine/moments", "machine/status"):
            self.speakers.allow(topic, self.peer_names["machine"])
        for topic in ("governor/state", "governor/events"):
            self.speakers.allow(topic, self.peer_names["governor"])
        for topic in ("machine/moments", "governor/state"):  # what the recording and the CSV are made of
            self.refusals.alters_when_unnamed(
                topic,
                "it may be the run's own node, named by the graph too late (nodes/trust.py NAME_WAIT): its samples "
                "are then missing from the recording",
            )
        self.own_name = self.get_name()  # (for the summary, written after Ctrl-C may have shut rclpy down)
        self.speakers.allow("/diagnostics", self.own_name, *self.peer_names.values())
        self.reports: dict[str, Report] = {}  # peer node -> what it refused and what disturbed it, from its latest
        # diagnostics
        governor_states = receive(
            self, JointState, "governor/state", self.on_governor, RECORD_QOS, self.refusals, self.speakers
        )
        self.streams = [governor_states] if self.model.governor is not None else []
        events = receive(
            self, String, "governor/events", self.on_governor_event, STATE_QOS, self.refusals, self.speakers
        )
        diagnostics_subscription = receive(
            self,
            DiagnosticArray,
            "/diagnostics",
            self.on_diagnostics,
            50,
            self.refusals,
            self.speakers,
            pass_speaker=True,
        )  # (every message: a stranger's status, whatever it names, is refused and counted by who sent it)
        status = follow_run_state(self, self.on_run_state, self.refusals, self.speakers)
        self.checked = [*self.streams, events, diagnostics_subscription, status]  # (trust.receive's: take_what_waits)
        self.create_timer(FLUSH_PERIOD, self.flush)
        self.create_timer(DIAGNOSTICS_PERIOD, self.report)
        self.get_logger().info(f"recording to {self.path if self.path is not None else connect}")

    def new_rows(self) -> RunRows:
        """The store of a trial's exchanges: its CSV next to the recording (none without a recording file), its spool
        in the recording's folder."""
        return RunRows(
            self.model,
            self.controller == "external",
            self.path.with_suffix(".csv") if self.path is not None else None,
            self.path.parent if self.path is not None else None,
            self._write,
            lambda line: self.get_logger().warning(line),
        )

    def flush(self) -> None:
        """Write the exchanges whose throttle is settled to the CSV, and send the recording's buffered samples to a
        live viewer, or to the file alone once RECORDING_CHUNK exchanges are in."""
        if self.live or self.unsent >= RECORDING_CHUNK:
            self.recording.flush()
            self.unsent = 0
        self.rows.write(self.throttle_settled_until(), self.tripped_at)

    def throttle_settled_until(self) -> float:
        """[s] up to which the exchanges' throttle is settled (RunRows.write): all once it comes from outside, the
        machine has tripped or has finished; else up to the machine's time in its latest diagnostics that said it
        had not tripped."""
        if self.controller == "external" or self.tripped_at is not None or self.finished_at is not None:
            return math.inf
        return self.untripped_until

    def start_trial(self, trial: int) -> None:
        """The machine's ~/reset (trial: the new trial's number): forget the samples of the trial before (the
        recording keeps them; the CSV starts again with the new trial's first rows)."""
        self.trial = trial
        self.rows.close()
        self.rows = self.new_rows()
        self.untripped_until = -math.inf
        self.events.clear()
        self.state_walls.clear()
        self.last_exchanges.clear()
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
        one recorded, read and checked as columns (common.batch_columns; every value read checked first,
        trust.BadMessage) and handed on a batch at a time."""
        needed = ["crank", "drive", "resistance", "external", "net", "load", "throttle"]
        needed += ["coupling"] if self.model.coupling is not None else []
        needed += ["driven"] if self.model.driven is not None else []
        batch = unrecorded(batch_columns(message, tuple(needed)), self.rows.newest[MACHINE], "machine/moments")
        joints, times = batch.joints, batch.times
        checked = [
            (joints["crank"].position, "crank position [rad]"),
            (joints["crank"].velocity, "crank velocity [rad/s]"),
        ]
        checked += [(joints[name].effort, f"{name} effort [N m]") for name in needed[1:6]]
        checked += [(joints["coupling"].position, "coupling position [rad]")] if "coupling" in joints else []
        checked += [(joints["driven"].velocity, "driven velocity [rad/s]")] if "driven" in joints else []
        everywhere = np.full(len(checked), math.inf)
        bounded_rows(
            np.column_stack([values for values, _ in checked]),
            -everywhere,
            everywhere,
            lambda row, field: f"machine/moments at {seconds(int(times[row])):.9g} s: {checked[field][1]}",
        )
        if times.size:
            phi, omega = joints["crank"].position, joints["crank"].velocity
            driven = {}
            if "coupling" in joints:
                driven["twist"] = joints["coupling"].position
            if "driven" in joints:
                driven["omega_driven"] = joints["driven"].velocity
            walls = self.state_walls[:1] + batch.walls.tolist()  # when the machine published those states
            self.state_walls = walls[:1] + walls[1:][-1:]  # the first and the latest
            self.last_exchanges = (self.last_exchanges + times[-2:].tolist())[-2:]
            self.unsent += times.size
            loads, throttle = joints["load"].effort, joints["throttle"].position
            self.recording.add_machines(  # each set point at the load of the sample before (as one by one)
                times, phi, omega, driven or None, np.append(self.recording.external_load, loads[:-1])
            )
            self.recording.add_moments(
                times,
                joints["drive"].effort,
                joints["resistance"].effort,
                joints["external"].effort,
                joints["net"].effort,
            )
            self.recording.add_external_loads(times, loads)  # a ramp becomes one event, a jump a step
            self.rows.add_machines(times, np.column_stack([phi, omega, *driven.values()]), loads, throttle)
            if self.controller == "external":
                self.recording.add_throttles(times, throttle)
        self.say_progress()

    def on_governor(self, message: JointState) -> None:
        """The governor's state at one or more exchange times (common.Batch), in order, after the last one recorded,
        read and checked as columns (common.batch_columns; every value read checked first, trust.BadMessage) and
        handed on a batch at a time."""
        if self.model.governor is None:
            raise BadMessage("no governor", f"scene '{self.model.scene.name}' has no governor")
        shown = self.model.governor.joints()  # GovernorKind.joints: (joint, position's key, velocity's key or None)
        batch = unrecorded(
            batch_columns(message, tuple(name for name, _, _ in shown)), self.rows.newest[GOVERNOR], "governor/state"
        )
        joints, times = batch.joints, batch.times
        checked = [
            values
            for name, _, velocity in shown
            if name != "throttle"
            for values in (
                (joints[name].position, joints[name].velocity) if velocity is not None else (joints[name].position,)
            )
        ]
        low, high = np.full(len(checked) + 1, -math.inf), np.full(len(checked) + 1, math.inf)
        low[-1], high[-1] = 0.0, 1.0  # the throttle [-], checked after the others of its row
        bounded_rows(
            np.column_stack([*checked, joints["throttle"].position]),
            low,
            high,
            lambda row, field: (
                f"governor/state at {seconds(int(times[row])):.9g} s" + (": throttle" if field == len(checked) else "")
            ),
        )
        if times.size:
            values = {position: joints[name].position for name, position, _ in shown}
            values.update({velocity: joints[name].velocity for name, _, velocity in shown if velocity is not None})
            self.rows.add_governors(times, values)
            self.recording.add_governors(times, values)
        self.say_progress()

    def say_progress(self) -> None:
        """Publish recorder/progress: the newest exchange time [ns] up to which every stream the run needs has been
        taken (its header's stamp), so that the machine keeps within RECORDER_LEAD exchanges of it
        (MachineNode.keep_pace_with_the_recorder)."""
        newest = [self.rows.newest[stream] for stream in ((MACHINE, GOVERNOR) if self.rows.governed else (MACHINE,))]
        if None not in newest:
            self.progress_publisher.publish(Header(stamp=stamp(min(newest))))

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
            else:
                self.untripped_until = max(self.untripped_until, when)
            self.machine_reported_end = self.machine_reported_end or "finished_at_ns" in values
            if exchanges is not None:
                self.machine_exchanges = int(exchanges)

    def complete(self) -> bool:
        """Whether the machine finished and its last samples (and the governor's) and its last diagnostics are in."""
        return self.machine_reported_end and self.last_samples_in()

    def machine_gone(self) -> bool:
        """Whether the machine has sent samples and no longer publishes them: its node ended, or its lease ran out
        while this process was stopped (docs/ros.md, "A recorder that falls behind"), before its end (`finished` on
        machine/status, kept for late readers) reached the recorder."""
        return self.rows.received[MACHINE] > 0 and self.machine_moments.get_publisher_count() == 0

    def last_samples_in(self) -> bool:
        """Whether the machine has finished and its last samples (and the governor's) are in: complete() then waits
        for its last diagnostics only, which say what it refused and what disturbed it."""
        return self.finished_at is not None and all(
            self.rows.received_until(stream, self.finished_at) for stream in (MACHINE, GOVERNOR)
        )

    def machine_failed(self) -> bool:
        """Whether the machine ended its run by itself other than complete (its solver status failed: a blow-up,
        driven backwards, no progress)."""
        return self.machine_result[0] not in ("complete", "interrupted")

    def all_that_can_come(self) -> bool:
        """Whether, the machine having failed (machine_failed), every sample that can still come is in: the machine's
        own up to its end and its last diagnostics, the governor's of every exchange before the machine's last, and of
        the last one too or else the governor's state stream has no publisher left (its node has ended, and a node
        ends only once its subscribers have acknowledged what it sent: common.deliver_all). The governor does not
        answer a state it refuses (beyond its speed range, where a run driven backwards fails), and a recorder that
        waited FINISH_GRACE for it would end every such run 10 s late."""
        if self.finished_at is None or not self.machine_failed() or not self.machine_reported_end:
            return False
        if not self.rows.received_until(MACHINE, self.finished_at):
            return False
        before = self.last_exchanges[0] if len(self.last_exchanges) == 2 else None  # the exchange before the last
        return (before is None or self.rows.received_until(GOVERNOR, before)) and (
            self.rows.received_until(GOVERNOR, self.finished_at)
            or all(stream.get_publisher_count() == 0 for stream in self.streams)
        )

    def close(self) -> None:
        """Write the last complete exchanges to the CSV (the rows before are in it already), finish the recording,
        then write the bag and the summary (JSON) next to it, from the run read back (RunRows.cosimulation); stopped
        before a first complete exchange, the summary alone (status interrupted, samples 0). Each output is written
        on its own: one that cannot be written (a disk that filled up) is said in one line on stderr and kept in
        write_failures, and the others are still written; nothing here raises."""
        if self.closed:
            return
        self.closed = True
        self.rows.write(math.inf, self.tripped_at)
        run_data = self.rows.cosimulation(self.events, self.tripped_at)
        self.rows.close()
        status, message = "interrupted", "before the first complete exchange"
        if run_data is not None:
            status, message = (
                cosimulation_ending(run_data)
                if self.complete()
                else (
                    "interrupted",
                    f"the recording stops at t = {run_data.times[-1]:.6g} s"
                    + (
                        ", every exchange in, but the machine's last diagnostics (what it refused, what disturbed "
                        "it) did not come"
                        if self.last_samples_in()
                        else ""
                    )
                    + self.held_back(),
                )
            )
            if self.machine_failed():  # the machine's own end
                status, message = self.machine_result
            elif self.missed():
                status, message = (
                    "interrupted",
                    (
                        f"{self.missed()} of the {self.machine_exchanges} exchanges the machine published are "
                        "incomplete here (a part never came: a peer fell silent, or the recorder fell behind more "
                        'than the publishers keep, docs/speed.md, "The nodes\' side of an exchange")'
                    )
                    + self.held_back(),
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
        summary = summarise_cosimulation(
            self.model, run_data, self.exchange_step, self.coupling, self.exchange_tolerance
        )
        summary.update(self.pace())
        if not self.complete() or self.machine_failed() or self.missed():
            summary["status"], summary["message"] = status, message  # the recording's end, said the same way
        summary.update(self.trust_summary(summary["status"]))
        summary["recording"] = str(self.path)
        if not self.rows.csv_failed:
            summary["csv"] = str(self.path.with_suffix(".csv"))
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

    def held_back(self) -> str:
        """What an interrupted run's message adds when one wait of the recorder for its callbacks took more than
        HELD_BACK s (its process stopped or starved): how long at most, and that a reader silent for longer than the
        participants' lease (PARTICIPANT_LEASE) is taken for gone, the machine then going on without it (docs/ros.md,
        "A recorder that falls behind"); else ''."""
        if self.longest_hold <= HELD_BACK:
            return ""
        return (
            f"; the recorder's process was held back (stopped or starved) for {self.longest_hold:.0f} s of wall time "
            f"at once (a reader silent for longer than the participants' lease, {PARTICIPANT_LEASE:g} s in the run's "
            "Fast DDS profile and 20 s by Fast DDS's default, is taken for gone and the machine goes on without it)"
        )

    def trust_summary(self, status: str) -> dict:
        """The summary's `refused` (topic -> reason -> count), `foreign` (sender -> topic -> count of the messages
        refused for who sent them; both summed over the nodes that refused) and `disturbances` ('<node>: <what>') when
        there are any; status `disturbed` (and the disturbances as its message) when one may have changed the numbers
        of a run that was otherwise complete."""
        own = self.refusals
        reports = {
            **self.reports,
            self.own_name: Report(own.counts, own.foreign, own.disturbances, own.alters_results),
        }
        refused: dict[str, dict[str, int]] = {}
        foreign: dict[str, dict[str, int]] = {}
        disturbances: list[str] = []
        alters = False
        for node, report in sorted(reports.items()):
            merge_counts(refused, report.counts)
            merge_counts(foreign, report.foreign)
            disturbances += [f"{node}: {text}" for text in report.disturbances]
            alters = alters or report.alters_results
        summary: dict = {}
        if refused:
            summary["refused"] = refused
        if foreign:
            summary["foreign"] = foreign
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
        first, last = self.rows.first_machine, self.rows.newest[MACHINE]
        if len(self.state_walls) < 2 or self.state_walls[1] <= self.state_walls[0] or first is None or last is None:
            return {}
        wall = self.state_walls[1] - self.state_walls[0]
        pace = {"wall_time_s": wall, "real_time_factor": (seconds(last) - seconds(first)) / wall}
        if self.launched_at > 0.0 and self.trial == 1:
            pace["start_up_s"] = self.state_walls[0] - self.launched_at
        if self.max_lag is not None:
            pace["max_lag_s"] = self.max_lag
        return pace

    def received(self) -> str:
        """What came of each stream: how many exchange times and the last one [s], e.g. 'machine states and
        moments: 301 up to 0.3 s; governor states: 301 up to 0.3 s'."""
        streams = {"machine states and moments": MACHINE}
        if self.model.governor is not None:
            streams["governor states"] = GOVERNOR
        return "; ".join(
            f"{name}: {self.rows.received[stream]}"
            + (f" up to {seconds(newest):.6g} s" if (newest := self.rows.newest[stream]) is not None else "")
            for name, stream in streams.items()
        )

    def missed(self) -> int:
        """How many of the exchanges the machine said it published in the trial (its last diagnostics) are not
        complete here: a recorder stalled longer than the publishers' histories (common.BATCH_HISTORY_DEPTH batches)
        misses the oldest; 0 while the machine has not said."""
        if self.machine_exchanges is None:
            return 0
        return max(self.machine_exchanges - self.rows.completed, 0)

    def report(self) -> None:
        """Publish /diagnostics: how many complete exchanges are recorded and up to which time."""
        values = {
            "scene": self.model.scene.name,
            "recorded_exchanges": self.rows.completed,
            "recorded_until": seconds(self.rows.completed_until) if self.rows.completed_until is not None else None,
        }
        level, text = self.refusals.status(OK, "recording")
        array = diagnostics(self, level, text, values)
        array.status[0].values += self.refusals.key_values()
        self.diagnostics_publisher.publish(array)

    def take_what_waits(self) -> None:
        """Take what waits in every subscription's reader straight from it (common.take_waiting), after each spin:
        after the recorder's process had been stopped for 90 s, rclpy's EventsExecutor was seen to hand over nothing
        more (its reader filled, acknowledged nothing, and the machine waited for it)."""
        for subscription in (self.machine_moments, *self.checked):
            take_waiting(subscription)

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
        self.machine_moments = receive(
            self, JointState, "machine/moments", self.on_moments, RECORD_QOS, self.refusals, self.speakers
        )

    def record(self) -> None:
        """Subscribe to the machine (subscribe_to_the_machine), then spin until the machine has finished and
        everything is in, after a failed run everything that can still come (all_that_can_come), or Ctrl-C; should
        the last samples not come within FINISH_GRACE s of wall time of the machine's end (or of its leaving without
        its end reaching the recorder) and of the latest sample taken, close with what there is (the summary says where
        it stops)."""
        self.subscribe_to_the_machine()
        taken = 0  # the samples taken so far (of both streams)
        waiting_since = time.monotonic()  # [s] wall time since which nothing came that the end waits for
        while rclpy.ok() and not self.complete():
            before = time.monotonic()
            spin_once(self, IDLE_SPIN_SLICE)
            self.take_what_waits()
            now = time.monotonic()
            received = sum(self.rows.received.values())
            self.longest_hold = max(self.longest_hold, now - before)
            if received != taken or now - before > HELD_BACK:
                # samples still come (a recorder catching up), or this process was held back (stopped, starved):
                # the grace starts again
                taken, waiting_since = received, now
            if self.finished_at is None:
                if not self.machine_gone():
                    waiting_since = now
                elif now - waiting_since > FINISH_GRACE:
                    self.get_logger().warning(
                        f"the machine left without its end reaching the recorder: closing with what was received "
                        f"({self.received()}){self.held_back()}"
                    )
                    break
                continue
            if self.all_that_can_come():
                self.get_logger().info(
                    f"the machine failed at t = {seconds(self.finished_at):.6g} s: closing with all that can "
                    f"still come ({self.received()})"
                )
                break
            if now - waiting_since > FINISH_GRACE:
                missing = "its last diagnostics" if self.last_samples_in() else "its last samples"
                self.get_logger().warning(
                    f"the machine finished at t = {seconds(self.finished_at):.6g} s but {missing} did not come "
                    f"within {FINISH_GRACE:g} s: closing with what was received ({self.received()})"
                )
                break
        self.close()
        if self.write_failures:  # said one by one already; the node ends with exit code 1
            raise OutputError(f"{len(self.write_failures)} output(s) could not be written: {self.write_failures[-1]}")


def unrecorded(batch: BatchColumns, newest: int | None, topic: str) -> BatchColumns:
    """The groups of a batch (common.batch_columns) at exchange times after `newest` [ns] (the newest of a stream
    recorded, None: none yet), each time once: the machine publishes an exchange time again when no answer
    came within machine.RESEND_PERIOD (a loaded machine), and its governor then answers that time twice, the repeat in the
    same batch or opening the next; the first answer is the one recorded. A batch from before the newest time
    recorded is refused (trust.BadMessage)."""
    times = batch.times
    if times.size and newest is not None and times[0] < newest:
        raise BadMessage("out of order", f"{topic} from {seconds(int(times[0])):.9g} s after {seconds(newest):.9g} s")
    fresh = times != (newest if newest is not None else -1)  # (the times are not decreasing: batch_columns)
    fresh[1:] &= times[1:] != times[:-1]
    return batch if fresh.all() else batch.rows(fresh)


def main() -> int:
    """Entry point of recorder_node."""
    return run(RecorderNode, RecorderNode.record)


if __name__ == "__main__":
    sys.exit(main())
