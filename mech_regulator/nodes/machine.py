"""machine_node: the machine of a scene, simulated by the core, exchanging signals over ROS topics.

Subscribes `throttle` (sensor_msgs/JointState, joint "throttle", position 0..1, stamped with the
simulation time it applies from), `load_torque` (std_msgs/Float64 [N m], the external load moment
opposing motion, from any publisher; applied from the next exchange time on) and
`load_torque_stamped` (geometry_msgs/WrenchStamped, torque.z [N m] applying from its stamp: the
scenario's load in lockstep; force.z: its rate [N m/s] over the step, a ramp's, which the corrected coupling
follows; force.x: the time [s] up to which, not including it, the load holds, rate and all, at the exchange times
after the stamp too, which then wait for no other answer; 0 or not above the stamp: that exchange time only). Publishes `joint_states` (joint "crank": phi [rad], omega [rad/s],
effort = net moment [N m]; "slider" x [m], v [m/s] or "rocker" angle [rad], rate [rad/s] when the
scene has a mechanism), `machine/moments` (what the recorder reads, sensor_msgs/JointState: the joints "drive",
"resistance", "external", "net" whose efforts are the moments on the crank by source, "load" the applied load
[N m], "throttle" (position: the throttle applied over the step [-]), and the state as in joint_states: "crank"
phi [rad], omega [rad/s], a two-mass machine's "coupling" twist [rad] and "driven" omega_driven [rad/s]; several exchange times in one message, each group opened by a joint "stamp"
whose velocity is the wall-clock time [s, time.monotonic] at which that exchange's joint_states went out:
common.Batch), `/clock` (at most every `clock_period` s of
wall time: the other nodes' timers need no more), `load_request` (std_msgs/Header stamped with an exchange time
whose load no answer of the scenario covers, in lockstep: the scenario answers it) and `/diagnostics`.

A two-mass machine adds the joints "coupling" (position: twist [rad]) and "driven" (position: phi_driven
[rad], NaN behind a clutch; velocity: omega_driven [rad/s]) to `joint_states`. `machine/status`
(std_msgs/String, JSON, transient-local: common.RunState) says whether the run is running, paused, holding
at its end or finished; the other nodes end by themselves when it is finished.

Time modes: `lockstep` advances exchange step by exchange step, waiting at each exchange time for the
inputs listed in `lockstep_inputs` stamped with that time (reproducible to the last digit, the same
numbers as mech_regulator.solvers.cosim.cosimulate; with `exchange_tolerance` > 0 the machine chooses each
exchange time, solvers.cosim.ExchangeTimes, and sends it as the end of its predicted samples); `realtime` follows the
wall clock scaled by `real_time_factor` with the newest inputs, and says how far its published state fell behind the wall clock at most
(`max_lag_s` [s of simulation time] in /diagnostics and machine/status; the recorder's summary has it). What it
waits for comes from the scene: the throttle when it has a governor (or `controller` is external: a node the user
starts, waited for by topic, not by name, and the run ends naming it when it does not answer within `peer_timeout`:
nodes.controller), the scenario's load; before the first
step, the `peers` (node names) that give them must subscribe to `joint_states` (or, as the recorder, to
`machine/moments`), or the machine ends within
`peer_timeout` naming the missing ones. A governor
that stays silent longer than `throttle_timeout` (realtime) or `peer_timeout` (lockstep) puts the machine on
its fail-safe (`fail_safe`: hold the last throttle or close it); `overspeed_trip` closes the throttle for
good above that speed.

Services (std_srvs/Trigger), for trials one after another as with a simulator's world: `~/pause` (the run
stops at the next exchange time), `~/resume`, `~/step` (advance `step_exchanges` exchanges, then stay
paused), `~/reset` (back to the scene's initial state at t = 0; the governor and the scenario follow when
they see time start again at 0). At the end of the scenario the machine finishes (`at_end: exit`) or holds,
paused, for a `~/reset` (`at_end: hold`).

This module is the node's ROS plumbing (parameters, topics, services, the run's loop); the exchange's bookkeeping
(the inputs' messages checked and kept, the step for each coupling, machine/moments' and /diagnostics' contents) is
nodes/machine_exchange.py's, mixed into MachineNode.
"""

from __future__ import annotations

import json
import math
import sys
import time

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import WrenchStamped
from rclpy.duration import Duration
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, Header, String
from std_srvs.srv import Trigger

from mech_regulator.nodes import controller
from mech_regulator.nodes.common import (
    ACK_CATCH_UP,
    ACK_PATIENCE,
    BATCH_QOS,
    COMMAND_QOS,
    PARTICIPANT_LEASE,
    PROGRESS_EVERY,
    PROGRESS_QOS,
    RECORDER_LEAD,
    STATE_QOS,
    STATUS_QOS,
    Batch,
    JointMessage,
    PeerError,
    RunState,
    SteadyNode,
    bool_parameter,
    coupling_parameter,
    deliver_all,
    exchange_tolerance_parameter,
    float_parameter,
    int_parameter,
    list_parameter,
    peer_parameter,
    run,
    scene_model,
    spin_once,
    stamp,
    take_waiting,
    text_parameter,
)
from mech_regulator.nodes.controller import CONTROLLERS
from mech_regulator.nodes.machine_exchange import MachineExchange
from mech_regulator.nodes.trust import (
    Refusals,
    Speakers,
    namesakes,
    receive,
    stamp_of,
)
from mech_regulator.nodes.wire import JointStateReader
from mech_regulator.scene import SceneError
from mech_regulator.solvers.cosim import MachineStepper, exchange_times_refusal, seconds, to_nanoseconds

LOCKSTEP_INPUTS = {"throttle": ("governor", "throttle"), "load": ("scenario", "load_torque_stamped")}  # input ->
# (the node that gives it by default, its topic)
DIAGNOSTICS_PERIOD = 1.0  # [s] of wall time between diagnostics
SPIN_SLICE = 0.02  # [s] of wall time per wait for messages
RESEND_PERIOD = 1.0  # [s] of wall time after which a lockstep exchange time is published again


class MachineNode(MachineExchange, SteadyNode):
    """The machine of `scene_file` (see the module docstring for topics and parameters)."""

    def __init__(self):
        super().__init__("machine")
        self.model = scene_model(self)
        governed = self.model.governor is not None
        self.time_mode = text_parameter(
            self, "time_mode", "lockstep", "how simulation time advances", ("lockstep", "realtime")
        )
        self.step_ns = to_nanoseconds(
            float_parameter(
                self,
                "exchange_step",
                self.model.scene.solver.exchange_step,
                "exchange step h [s]: inputs are held and outputs published "
                "every h of simulation time (default: the scene's "
                "solver.exchange_step)",
                1e-6,
                1.0,
                read_only=True,
            )
        )
        duration = float_parameter(
            self, "duration", 0.0, "simulated time [s] to run; 0: the scene's duration", 0.0, 1e7, read_only=True
        )
        self.end_ns = to_nanoseconds(duration or self.model.scene.scenario.duration)
        self.real_time_factor = float_parameter(
            self, "real_time_factor", 1.0, "realtime: simulated seconds per wall-clock second", 1e-3, 1e3
        )
        self.throttle_timeout = float_parameter(
            self,
            "throttle_timeout",
            0.1,
            "realtime: fail-safe when the newest throttle is older than this [s of simulation time]",
            1e-6,
            3600.0,
        )
        self.peer_timeout = float_parameter(
            self,
            "peer_timeout",
            10.0,
            "lockstep: wall-clock seconds to wait for an input before going on without it (fail-safe)",
            0.01,
            3600.0,
        )
        self.fail_safe = text_parameter(
            self, "fail_safe", "close", "throttle while the governor is silent", ("hold", "close"), read_only=False
        )
        self.max_load_torque = float_parameter(
            self, "max_load_torque", 1e5, "load messages beyond +- this [N m] are rejected", 0.0, 1e12
        )
        overspeed = float_parameter(
            self,
            "overspeed_trip",
            0.0,
            "trip speed [rad/s]: above it the throttle closes for good; 0: no trip",
            0.0,
            1e9,
            read_only=True,
        )
        self.controller = text_parameter(
            self,
            "controller",
            "governor",
            "what gives the throttle: the scene's "
            "governor (governor_node) or external, a node the user starts (the machine "
            "waits for it by topic, not by name; docs/ros.md, Your own controller)",
            CONTROLLERS,
        )
        external = self.controller == "external"
        self.controllers: list[str] = []  # the nodes that publish throttle at the start (external controller)
        inputs = list_parameter(
            self,
            "lockstep_inputs",
            ["throttle", "load"] if governed or external else ["load"],
            "lockstep: inputs to wait for at every exchange time: throttle, load (default: the "
            "throttle when the scene has a governor or controller is external, and the "
            "scenario's load)",
        )
        self.lockstep_inputs = [item for item in inputs if item]
        unknown = [item for item in self.lockstep_inputs if item not in LOCKSTEP_INPUTS]
        if unknown:
            raise SceneError(
                f"parameter lockstep_inputs = {inputs}: unknown {unknown}; expected a list of "
                f"{', '.join(LOCKSTEP_INPUTS)}"
            )
        if "throttle" in self.lockstep_inputs and not governed and not external:
            raise SceneError(
                f"parameter lockstep_inputs = {inputs}: scene '{self.model.scene.name}' has no governor "
                "to give a throttle; leave 'throttle' out, or set controller to external"
            )
        default_peers = (
            [LOCKSTEP_INPUTS[item][0] for item in self.lockstep_inputs if not (external and item == "throttle")]
            if self.time_mode == "lockstep"
            else []
        )
        peers = list_parameter(
            self,
            "peers",
            default_peers or [""],
            "node names that must subscribe to joint_states "
            "before the first step (default: those giving the lockstep inputs)",
        )
        self.peers = [item for item in peers if item]
        self.at_end = text_parameter(
            self, "at_end", "exit", "at the end of the scenario: exit, or hold (paused) until ~/reset", ("exit", "hold")
        )
        self.step_exchanges = int_parameter(
            self, "step_exchanges", 1, "exchanges advanced by one ~/step call", 1, 10**9, read_only=False
        )
        self.publish_clock = bool_parameter(self, "publish_clock", True, "publish the simulation time on /clock")
        self.clock_period = float_parameter(
            self,
            "clock_period",
            0.02,
            "wall-clock seconds between /clock messages "
            "(at most; the first and last exchange times are always published); 0: "
            "every exchange time",
            0.0,
            3600.0,
        )
        self.last_clock = -math.inf  # wall-clock time [s] of the last /clock message

        self.overspeed = overspeed
        coupling = coupling_parameter(self)
        self.exchange_tolerance = exchange_tolerance_parameter(self)
        refusal = exchange_times_refusal(seconds(self.end_ns), seconds(self.step_ns), self.exchange_tolerance, coupling)
        if refusal is not None:
            raise SceneError(refusal)
        self.waveform = coupling == "waveform" and governed
        self.corrects = coupling == "corrected" and governed
        self.follows_ramps = coupling == "corrected"  # the load's rate over a step (force.z of the stamped load)
        self.trial = 0
        self.start_trial()
        MachineStepper(self.model, self.overspeed).advance(
            seconds(min(self.step_ns, self.end_ns)), self.throttle, self.load
        )  # thrown away: see run()
        self.paused = bool_parameter(self, "start_paused", False, "start paused (~/resume or ~/step to go on)")
        self.steps_left = 0  # exchanges ~/step still allows while paused
        self.reset_requested = False
        self.refusals = Refusals(self, lambda: self.report(force=True))
        self.speakers = Speakers(self)
        governor_name = peer_parameter(self, LOCKSTEP_INPUTS["throttle"][0])
        self.speakers.allow("throttle", *(() if self.controller == "external" else (governor_name,)))
        if self.controller == "external":  # (docs/ros.md, "Who may speak": what the machine cannot refuse)
            self.refusals.alters_when_refused(
                "throttle",
                "second publisher",
                "the machine takes the throttle of the node that published it first and cannot tell which of the two "
                "is your controller",
            )
        self.scenario_name = peer_parameter(self, LOCKSTEP_INPUTS["load"][0])
        self.speakers.allow("load_torque_stamped", self.scenario_name)
        self.recorder_name = peer_parameter(self, "recorder")
        self.speakers.allow("recorder/progress", self.recorder_name)
        self.recorded_ns: int | None = None  # the newest exchange time the recorder has taken (recorder/progress)
        self.namesakes: set[str] = set()  # names of this run's nodes seen twice on the domain (reported once)

        self.joint_publisher = self.create_publisher(JointState, "joint_states", STATE_QOS)
        self.load_request_publisher = self.create_publisher(Header, "load_request", COMMAND_QOS)
        self.moments = Batch(
            self.create_publisher(JointState, "machine/moments", BATCH_QOS),
            self.get_logger().warning,
            self.complete_moments,
        )
        self.clock_publisher = self.create_publisher(Clock, "/clock", 10) if self.publish_clock else None
        self.diagnostics_publisher = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.status_publisher = self.create_publisher(String, "machine/status", STATUS_QOS)
        for name, callback in (
            ("reset", self.on_reset),
            ("pause", self.on_pause),
            ("resume", self.on_resume),
            ("step", self.on_step),
        ):
            self.create_service(Trigger, f"~/{name}", callback)
        for message_type, topic, handle in (
            (JointState, "throttle", self.on_throttle),
            (Float64, "load_torque", self.on_load),  # from anyone
            (WrenchStamped, "load_torque_stamped", self.on_stamped_load),
        ):
            receive(
                self,
                message_type,
                topic,
                handle,
                COMMAND_QOS,
                self.refusals,
                self.speakers,
                pass_speaker=topic == "load_torque",  # (a load poked from outside: MachineExchange.on_load)
                reader=JointStateReader() if topic == "throttle" else None,  # the critical path's answer as bytes
            )
        self.recorder_progress = receive(
            self, Header, "recorder/progress", self.on_recorder_progress, PROGRESS_QOS, self.refusals, self.speakers
        )
        self.add_post_set_parameters_callback(self.on_parameters)
        self.now_ns = 0
        self.state_message = JointMessage()  # joint_states, refilled at every exchange
        self.wall_start = time.monotonic()
        self.last_diagnostics = -math.inf

    # ---------------------------------------------------------------------------------------------
    # Services: trials one after another.

    def called_from_outside(self, service: str) -> None:
        """Note a call of ~/<service> as a disturbance (the run's own nodes call none), with the nodes that have a
        client of it: who may have called (a service request does not name its sender in rclpy)."""
        name = f"{self.get_fully_qualified_name()}/{service}"
        try:
            callers = [
                node
                for node, namespace in self.get_node_names_and_namespaces()
                if node != self.get_name()
                and any(client == name for client, _ in self.get_client_names_and_types_by_node(node, namespace))
            ]
        except Exception:  # a node that left while the graph was read
            callers = []
        self.refusals.disturb(
            f"{name} called at t = {seconds(self.now_ns):.9g} s (trial {self.trial}) by "
            f"{' or '.join(callers) or 'a node the graph does not name (yet, or any more)'}",
            alters_results=False,
        )

    def on_reset(self, request, response):
        self.called_from_outside("reset")
        self.reset_requested = True
        response.success, response.message = (
            True,
            (
                f"trial {self.trial} stops at t = {seconds(self.now_ns):.9g} s; "
                f"trial {self.trial + 1} starts from the initial state at t = 0"
            ),
        )
        return response

    def on_pause(self, request, response):
        self.called_from_outside("pause")
        self.paused, self.steps_left = True, 0
        response.success, response.message = True, f"paused at t = {seconds(self.now_ns):.9g} s"
        self.publish_status()
        return response

    def on_resume(self, request, response):
        self.called_from_outside("resume")
        self.paused, self.steps_left = False, 0
        response.success, response.message = True, f"running from t = {seconds(self.now_ns):.9g} s"
        self.publish_status()
        return response

    def on_step(self, request, response):
        self.called_from_outside("step")
        self.paused = True
        self.steps_left += self.step_exchanges
        response.success, response.message = (
            True,
            (f"advancing {self.steps_left} exchange(s) from t = {seconds(self.now_ns):.9g} s, then paused"),
        )
        return response

    # ---------------------------------------------------------------------------------------------
    # Parameters changed while running

    def on_parameters(self, parameters) -> None:
        """Apply the accepted changes (ranges and choices already checked) of the parameters that may
        change while running."""
        for parameter in parameters:
            if parameter.name in (
                "real_time_factor",
                "throttle_timeout",
                "peer_timeout",
                "max_load_torque",
                "fail_safe",
                "step_exchanges",
                "clock_period",
            ):
                if parameter.name == "real_time_factor":  # keep the simulation time continuous
                    self.wall_start = time.monotonic() - seconds(self.now_ns) / parameter.value
                setattr(self, parameter.name, parameter.value)

    # ---------------------------------------------------------------------------------------------
    # The run

    def run(self) -> None:
        """Wait for the peers, then step until the end (or Ctrl-C), publishing every exchange time; between
        exchanges, pause, step and reset as the services ask."""
        waited = time.monotonic()
        if self.controller == "external":
            self.get_logger().info(controller.contract(self.peer_timeout))
        self.wait_for_peers()
        self.controllers = controller.publisher_names(self)  # named should the controller die
        # The first log line and the first diagnostics take up to a tenth of a second each (so does the first
        # integration: done in __init__ on a stepper thrown away): before the clock starts, so that a realtime run does
        # not start behind it.
        self.get_logger().info(
            f"{self.time_mode} run starts: peers ({', '.join(self.peers) or 'none'}) there after "
            f"{time.monotonic() - waited:.3g} s"
        )
        self.report(force=True)
        self.wall_start = time.monotonic()
        self.publish_status()
        while rclpy.ok():
            self.now_ns, next_ns = self.exchanges.now, self.exchanges.next
            self.keep_pace_with_the_recorder()
            if self.corrects:  # the step predicted with the last step's load: the new one comes with the throttle
                self.predicted = (
                    self.stepper.predict(seconds(next_ns), self.tentative) if next_ns > self.now_ns else None
                )
            self.publish_state()
            self.request_load()
            self.moments.send_when_due()  # the last exchanges', sent while the peers answer this one
            if self.corrects and next_ns < self.end_ns:  # the next step's predictor, while the governor answers
                self.stepper.predict_ahead(seconds(self.exchanges.after_next()), self.tentative)
            self.add_moments()  # the last exchange's, while the peers answer this one
            self.report()  # /diagnostics when due (0.3-0.5 ms of CPU), while the peers answer this one
            if self.time_mode == "realtime" and next_ns > self.now_ns:
                self.wait_until(next_ns)  # the inputs that hold over the step are the newest at its end
            self.collect_inputs()
            throttle = self.stepper.applied_throttle(self.applied_throttle())
            self.held = (self.now_ns, self.stepper.time, self.stepper.state, throttle, self.load, self.published_at)
            at_end = self.now_ns >= self.end_ns or self.stepper.status != "complete"
            if at_end and (self.at_end == "exit" or self.stepper.status != "complete"):
                break
            self.wait_while_paused(holding=at_end)
            if self.reset_requested:
                self.send_moments()
                self.reset_requested = False
                self.start_trial()
                self.wall_start = time.monotonic()
                self.publish_status()
                self.get_logger().info(f"reset: trial {self.trial} starts from the initial state")
                continue
            self.advance(next_ns, throttle)
            self.exchanges.move_on(self.predicted, self.corrected, float(self.stepper.state[1]))
        if rclpy.ok():
            self.send_moments()
            self.finish()

    def on_recorder_progress(self, message: Header) -> None:
        """recorder/progress (speaker checked): the newest exchange time [ns] up to which the recorder has taken every
        stream."""
        self.recorded_ns = stamp_of(message.stamp)

    def read_recorder_progress(self) -> None:
        """Take what recorder/progress holds (on_recorder_progress) straight from the subscription (take_waiting): in
        the machine node the EventsExecutor was seen not to call this subscription's callback (its messages stayed in
        the reader; not traced), so the machine does not wait for the executor to hand them over."""
        take_waiting(self.recorder_progress)

    def keep_pace_with_the_recorder(self) -> None:
        """Before the exchange at now_ns: while the recorder has taken less than what the machine sent RECORDER_LEAD
        exchanges ago (recorder/progress), spin (serving the services) until it catches up, the run's time held; said
        on the log past ACK_PATIENCE s of wall time. A recorder slower than the machine (a loaded machine: the shaper
        through the nodes for 10 000 s ended with its recorder 5 minutes behind, 13 203 exchanges it had not yet taken
        lost with the machine) so sets the run's pace, and what it has not taken stays bounded (docs/ros.md, "A
        recorder that falls behind"). Not in realtime runs (the wall clock sets their pace), nor once the recorder has
        gone (no publisher of recorder/progress). A recorder still there that takes nothing for ACK_CATCH_UP s ends
        the run (PeerError: exit code 1, said), as a batch's wait for it does (common.wait_for_readers)."""
        if self.time_mode == "realtime" or self.published_exchanges % PROGRESS_EVERY:
            return
        self.read_recorder_progress()
        lead = RECORDER_LEAD * self.step_ns
        if self.recorded_ns is None or self.now_ns - self.recorded_ns <= lead:
            return
        waited, said = time.monotonic(), False
        taken, taken_at = self.recorded_ns, waited  # the recorder's progress and when it last advanced
        while rclpy.ok() and self.now_ns - self.recorded_ns > lead and self.recorder_progress.get_publisher_count():
            self.moments.send_when_due()
            spin_once(self, SPIN_SLICE)
            self.read_recorder_progress()
            self.report()
            if self.recorded_ns != taken:
                taken, taken_at = self.recorded_ns, time.monotonic()
            elif time.monotonic() - taken_at > ACK_CATCH_UP:
                raise PeerError(
                    f"the recorder is there but has taken nothing more for {ACK_CATCH_UP:g} s of wall time (it took "
                    f"the exchanges up to t = {seconds(self.recorded_ns):.6g} s; stopped, or resumed and no longer "
                    "receiving): the run ends; the recorder's summary says what it has"
                )
            if not said and time.monotonic() - waited > ACK_PATIENCE:
                self.get_logger().warning(
                    f"the recorder has taken the exchanges up to t = {seconds(self.recorded_ns):.6g} s only: the run "
                    f"waits at t = {seconds(self.now_ns):.6g} s until it is within {RECORDER_LEAD} exchanges"
                )
                said = True

    def wait_while_paused(self, holding: bool) -> None:
        """Between exchanges: spin (serving the services) while paused with no ~/step left, or while holding at
        the end; return when the run may advance or a reset is asked for."""
        if self.paused and self.steps_left > 0 and not holding:
            self.steps_left -= 1
            return
        if not (self.paused or holding):
            return
        self.send_moments()
        self.publish_status(RunState.HOLDING if holding else RunState.PAUSED)
        paused_at = time.monotonic()
        while rclpy.ok() and not self.reset_requested and (holding or self.paused and self.steps_left == 0):
            spin_once(self, SPIN_SLICE)
            self.report()
        self.wall_start += time.monotonic() - paused_at  # realtime: the pause does not count
        if not self.reset_requested:
            self.steps_left = max(self.steps_left - 1, 0)
            self.publish_status()

    def wait_for_peers(self) -> None:
        """Spin until every peer node (parameter peers) subscribes to joint_states, (the recorder) machine/moments or
        (the scenario in lockstep) load_request, raising PeerError that names the
        missing ones after peer_timeout seconds, and, for at most peer_timeout, until each lockstep input has a
        publisher (one still missing then is waited for at the first exchange and, silent, put on its fail-safe) and
        the state streams have matched every subscription the graph knows (matched_every_subscription): a short run
        could otherwise end before a stream matched the recorder, and its samples be lost with the machine."""
        waited = time.monotonic()
        topic = self.joint_publisher.topic_name
        namespace = self.get_namespace()
        while rclpy.ok():
            subscribed = {
                info.node_name
                for name in (topic, self.moments.publisher.topic_name, self.load_request_publisher.topic_name)
                for info in self.get_subscriptions_info_by_topic(name)
                if info.node_namespace == namespace
            }
            missing = [name for name in self.peers if name not in subscribed]
            twice = namesakes(self, [self.get_name(), *self.peers])
            if twice:
                named = ", ".join(repr(name) for name in twice)
                raise SceneError(
                    f"another node named {named} is on this ROS domain already (another run on the same "
                    f"--domain-id, or one killed there within the last {PARTICIPANT_LEASE:g} s: the domain forgets a "
                    "killed node only when its lease has passed): this run would take its messages and it this "
                    "run's; use another domain, or end the other run"
                )
            unpublished = [
                item for item in self.lockstep_inputs if self.count_publishers(LOCKSTEP_INPUTS[item][1]) == 0
            ]
            timed_out = time.monotonic() - waited > self.peer_timeout
            if self.controller == "external" and "throttle" in unpublished and timed_out:
                raise PeerError(controller.absent(self.peer_timeout))
            if missing and timed_out:
                raise PeerError(
                    f"machine: no {', '.join(missing)} node subscribed to {topic} (or "
                    f"{self.moments.publisher.topic_name}) within "
                    f"{self.peer_timeout:g} s (parameter peer_timeout): start it, or leave it out of the "
                    "parameter peers"
                )
            if not missing and (timed_out or not unpublished and self.matched_every_subscription()):
                return
            spin_once(self, SPIN_SLICE)

    def matched_every_subscription(self) -> bool:
        """Whether the state streams the recorder reads (joint_states, machine/moments, machine/status) and the
        scenario's load_request have matched every subscription the graph knows on their topics: a stream a peer
        subscribes to but that has not matched it yet would not deliver to it (common.deliver_all; a request lost so
        would be sent again only after RESEND_PERIOD)."""
        return all(
            publisher.get_subscription_count() >= self.count_subscribers(publisher.topic_name)
            for publisher in (
                self.joint_publisher,
                self.moments.publisher,
                self.status_publisher,
                self.load_request_publisher,
            )
        )

    def collect_inputs(self) -> None:
        """Take the inputs for the current exchange time: in lockstep, wait for each listed input stamped
        with it (or time out and go on without it); then apply the newest load."""
        if self.time_mode == "lockstep":
            waited = sent = time.monotonic()
            while rclpy.ok() and self.missing_inputs():
                spin_once(self, SPIN_SLICE)
                if time.monotonic() - sent > RESEND_PERIOD:  # a peer that matched late missed it: say it again
                    self.joint_publisher.publish(self.state_message.message)
                    self.request_load()
                    sent = time.monotonic()
                if time.monotonic() - waited > self.peer_timeout:
                    missing = self.missing_inputs()
                    if self.controller == "external" and "throttle" in missing:
                        self.end_without_controller()
                    self.silent.update(missing)
                    self.refusals.disturb(
                        f"no {' or '.join(missing)} for t = {seconds(self.now_ns):.9g} s within "
                        f"{self.peer_timeout:g} s (parameter peer_timeout: a lost or stalled peer); "
                        "going on without waiting, fail-safe applies",
                        alters_results=True,
                    )
                    self.report(force=True)
        else:
            spin_once(self, 0.0)
        stamped = self.stamped_load.pop(self.now_ns, None) or self.held_load()
        if stamped is not None:
            value, self.load_rate = stamped
            if value != self.last_stamped_load:  # only the scenario's changes: a load typed in between stays
                self.load = self.last_stamped_load = value
        for when in [when for when in self.stamped_load if when < self.now_ns]:  # too late to apply
            self.stamped_load.pop(when)
        if self.pending_load is not None:
            self.load, self.load_rate, self.pending_load = self.pending_load, 0.0, None

    def end_without_controller(self) -> None:
        """An external controller gave no throttle within peer_timeout: send what was computed (the recorder keeps
        it), then end naming the controller (PeerError: exit code 1)."""
        self.send_moments()
        self.moments.deliver()
        deliver_all(self, [self.joint_publisher])
        names = controller.publisher_names(self) or self.controllers
        raise PeerError(
            controller.silent(
                names,
                seconds(self.now_ns),
                self.peer_timeout,
                None if self.wrong_stamp is None else seconds(self.wrong_stamp),
            )
        )

    def wait_until(self, target_ns: int) -> None:
        """Realtime: spin until the wall clock reaches the simulation time target_ns / real_time_factor."""
        while rclpy.ok():
            remaining = self.wall_start + seconds(target_ns) / self.real_time_factor - time.monotonic()
            if remaining <= 0.0:
                return
            spin_once(self, min(remaining, SPIN_SLICE))

    # ---------------------------------------------------------------------------------------------
    # Outputs

    def publish_state(self) -> None:
        """joint_states and /clock at the current exchange time (effort: the net moment with the inputs held over the
        step that ended here); joint_states first: the governor answers it, and a node that follows /clock (use_sim_time)
        takes that message in Python before the next (docs/speed.md, "Where an exchange's 1.4 ms goes")."""
        wall = time.monotonic()
        if self.time_mode == "realtime":  # the wall clock's simulation time less the state's, at its publication
            self.max_lag = max(self.max_lag, (wall - self.wall_start) * self.real_time_factor - seconds(self.now_ns))
        net, others = self.stepper.message_outputs(self.throttle, self.load)
        joints = [("crank", float(self.stepper.state[0]), float(self.stepper.state[1])), *others]
        if self.omega_middle is not None:  # waveform coupling: the speed at the middle of the step that ended here
            joints.append(("crank_midstep", math.nan, self.omega_middle))
        names, positions, velocities = zip(*joints)
        message = self.state_message.fill(
            self.now_ns,
            names,
            positions,
            velocities,
            [net] + [math.nan] * (len(joints) - 1),  # the others' not computed
            (("crank_corrected", "velocity", self.corrected), ("crank_predicted", "velocity", self.predicted)),
        )  # corrected coupling: the speed over the step that ended here and as predicted over the next
        self.joint_publisher.publish(message)
        self.published_at = time.monotonic()
        self.published_exchanges += 1
        if self.clock_publisher is not None and (
            wall - self.last_clock >= self.clock_period or self.now_ns == 0 or self.now_ns >= self.end_ns
        ):
            self.clock_publisher.publish(Clock(clock=stamp(self.now_ns)))  # the others' timers need not every exchange
            self.last_clock = wall

    def request_load(self) -> None:
        """load_request stamped with the current exchange time, in lockstep when no load the scenario sent covers that
        time (held_load): the scenario answers it on load_torque_stamped. So the scenario reads one message per load
        event (at every exchange of a ramp), not every joint_states (docs/ros.md, "Time")."""
        if self.time_mode == "lockstep" and self.now_ns not in self.stamped_load and self.held_load() is None:
            self.load_request_publisher.publish(Header(stamp=stamp(self.now_ns), frame_id="crank"))

    def report(self, force: bool = False) -> None:
        """Publish /diagnostics every DIAGNOSTICS_PERIOD s of wall time (or now, when forced)."""
        wall = time.monotonic()
        if not force and wall - self.last_diagnostics < DIAGNOSTICS_PERIOD:
            return
        self.last_diagnostics = wall
        for name in set(namesakes(self, [self.get_name(), *self.peers])) - self.namesakes:
            self.namesakes.add(name)
            self.refusals.disturb(
                f"a second node named '{name}' appeared on the domain at t = "
                f"{seconds(self.now_ns):.9g} s; its messages are refused",
                alters_results=False,
            )
        self.diagnostics_publisher.publish(self.diagnostics())

    def publish_status(self, state: str | None = None) -> None:
        """machine/status: the run's state (RunState; by default running or paused), time, trial and solver
        status."""
        state = state or (RunState.PAUSED if self.paused and self.steps_left == 0 else RunState.RUNNING)
        status = {
            "state": state,
            "time": seconds(self.now_ns),
            "trial": self.trial,
            "status": self.stepper.status,
            "tripped_at": self.stepper.tripped_at,
        }
        if self.time_mode == "realtime":
            status["max_lag_s"] = self.max_lag
        if state == RunState.FINISHED:
            status["finished_at_ns"] = self.now_ns
        self.status_publisher.publish(String(data=json.dumps(status)))

    def finish(self) -> None:
        """Say the run is over (machine/status finished, diagnostics with finished_at_ns) once every subscriber
        has the last state, and wait until the readers have both (deliver_the_end: a recorder held back past ACK_WAIT
        would miss them, and a run with every exchange in would end `interrupted`)."""
        self.moments.deliver()
        deliver_all(self, [self.joint_publisher])
        self.publish_status(RunState.FINISHED)
        self.diagnostics_publisher.publish(self.diagnostics(finished=True))
        self.deliver_the_end()
        self.get_logger().info(f"finished at t = {seconds(self.now_ns):.6g} s: {self.stepper.status}")

    def deliver_the_end(self) -> None:
        """Wait until the readers of machine/status and /diagnostics have acknowledged the run's end (`finished`, the
        last diagnostics): every reader at most ACK_WAIT s per topic (deliver_all), then, should one still not have,
        as long as the recorder is subscribed to machine/status, at most ACK_CATCH_UP s (said past ACK_PATIENCE s). A
        recorder held back (its process stopped or starved) gets the end its `complete` summary needs, and it leaves
        the graph once it has it; a reader that will never answer (a node killed without leaving the graph, taken for
        there for the participants' lease: common.PARTICIPANT_LEASE) holds the machine no longer than the recorder
        stays (docs/ros.md, "A recorder that falls behind")."""
        publishers = [self.status_publisher, self.diagnostics_publisher]
        deliver_all(self, publishers)
        waited, said = time.monotonic(), False
        while (
            not all(publisher.wait_for_all_acked(Duration(seconds=SPIN_SLICE)) for publisher in publishers)
            and self.recorder_follows()
            and time.monotonic() - waited < ACK_CATCH_UP
        ):
            if not said and time.monotonic() - waited > ACK_PATIENCE:
                self.get_logger().warning(
                    f"the readers of {self.status_publisher.topic_name} (the recorder among them) have not "
                    f"acknowledged the run's end for {ACK_PATIENCE:g} s of wall time: the machine waits while the "
                    f"recorder is there, at most {ACK_CATCH_UP - ACK_PATIENCE:g} s more"
                )
                said = True

    def recorder_follows(self) -> bool:
        """Whether the recorder (parameter recorder_node, in this node's namespace) is subscribed to machine/status."""
        namespace = self.get_namespace()
        return any(
            info.node_name == self.recorder_name and info.node_namespace == namespace
            for info in self.get_subscriptions_info_by_topic(self.status_publisher.topic_name)
        )


def main() -> int:
    """Entry point of machine_node."""
    return run(MachineNode, MachineNode.run)


if __name__ == "__main__":
    sys.exit(main())
