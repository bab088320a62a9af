"""``prsm_health_node``: the health estimator as a ROS 2 lifecycle node.

Inputs: ``prsm_health_msgs/MotorState`` or ``sensor_msgs/JointState`` (the named joint; effort
is the motor current or torque) on ``input_topic``; their header stamps drive the filter.
Received samples are handed to :class:`HealthEstimator` every ``batch_period_s``.
Outputs: ``~/health`` (``HealthEstimate``, every estimate or at ``health_rate_hz``) and
``/diagnostics`` (``DiagnosticArray``, reliable, at ``diagnostics_rate_hz``; the statuses of
:mod:`prsm_health.outputs`). Timing of the diagnostics and of staleness uses the node's clock,
so ``use_sim_time`` works. The estimator state is saved (:mod:`prsm_health.ros.persistence`)
every ``save_period_s`` of steady time, on deactivate and on shutdown, and restored on
configure.

Lifecycle: configure (validate parameters, build the estimator, restore the state, create the
publishers), activate (subscribe, start the timers, publish), deactivate (process what was
received, save, stop: an inactive node publishes nothing), cleanup, shutdown (save). A node
whose configure failed stays unconfigured (its parameters can be fixed and configure called
again) and says why on ``/diagnostics`` until a configure succeeds. Until its first new
estimate, the diagnostics report the last estimate restored with the state, marked as such.
``autostart`` (default true) configures and activates at start. The node never crashes on
input: every callback catches its exceptions, counts them (filter-consistency status) and
logs at most once per second; non-finite outputs are replaced and counted.

Run: ``prsm-health-node --ros-args -p name:=value`` or ``python -m prsm_health.ros.node``.
SIGINT and SIGTERM shut it down cleanly with the state saved. docs/ros.md has the details.
"""

from __future__ import annotations

import dataclasses
import math
import sys
import time
from collections import Counter, defaultdict
from collections.abc import Sequence
from difflib import get_close_matches
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from prsm_health_msgs.msg import HealthEstimate, MotorState
from prsm_health_msgs.srv import ResetAfterMaintenance
from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    SetParametersResult,
)
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.parameter import Parameter
from rclpy.qos import QoSHistoryPolicy, QoSProfile, QoSReliabilityPolicy
from rclpy.utilities import ok, remove_ros_args
from sensor_msgs.msg import JointState

from prsm_health.estimation.estimate import HealthState
from prsm_health.estimation.estimator import HealthEstimator
from prsm_health.outputs import (
    DiagnosticStatusData,
    PersistenceHealth,
    configuration_status,
    health_estimate_fields,
    persistence_status,
    restored_statuses,
)
from prsm_health.ros.messages import (
    JOINT_PROBLEMS,
    diagnostic_array,
    health_estimate,
    input_sample,
)
from prsm_health.ros.parameters import (
    NODE_NAME,
    PARAMETERS,
    SPECS,
    ConfigError,
    NodeConfig,
    ParameterSpec,
    node_config,
    usage,
)
from prsm_health.ros.persistence import StateStore
from prsm_health.ros.runtime import ros_session
from prsm_health.signals import MotorSamples
from prsm_health.tracking import DiagnosticsTracker, rejected_by_reason

NS_PER_S = 1e9
#: Estimates kept for reliable subscribers: 20 s at 50 Hz (a replay at twice the speed), longer
#: than Fast DDS takes to repair a lost message (its 3 s heartbeat), so none is overwritten first.
HEALTH_QOS_DEPTH = 1000
DIAGNOSTICS_QOS = QoSProfile(depth=10, reliability=QoSReliabilityPolicy.RELIABLE)
#: Every maintenance-reset request is kept until answered: with the services' default
#: (KEEP_LAST 10) a burst of requests lost all but the last ten, whose callers never heard
#: back (50 at once: 10 answered in 20 s; KEEP_ALL: 50 in 0.06 s).
RESET_SERVICE_QOS = QoSProfile(
    history=QoSHistoryPolicy.KEEP_ALL, reliability=QoSReliabilityPolicy.RELIABLE
)
#: How often a node whose configure failed says so on /diagnostics (steady clock: also
#: while a sim-time /clock does not run) [s].
CONFIGURE_FAILED_PERIOD_S = 1.0
#: How often the main loop returns to Python to see a SIGINT/SIGTERM [s].
SPIN_TIMEOUT_S = 0.1
#: Parameters a configured node refuses to change: ours and the clock the diagnostics run on.
APPLIED_AT_CONFIGURE = frozenset({*SPECS, "use_sim_time"})
#: A text from a message (a maintenance note, a JointState's names) longer than this is
#: logged cut, with its length: a 1 MB note, or 20,000 joint names, made one log line of it.
LOGGED_TEXT_CHARS = 500
#: A kind of input the node rejects is logged at most once per this long [s].
REJECT_LOG_PERIOD_S = 5.0
#: An error caught around one place (an input, the processing, a save...) is logged at most
#: once per this long [s]; every one is counted.
FAULT_LOG_PERIOD_S = 1.0


class LogThrottle:
    """Whether a log line of some kind is due: at most one per ``period_s`` (steady clock),
    each kind apart (one throttle for all, rclpy's per call site, hid one kind behind
    another)."""

    def __init__(self, period_s: float) -> None:
        self._period_s = period_s
        self._logged_s: defaultdict[str, float] = defaultdict(lambda: -math.inf)

    def due(self, kind: str) -> bool:
        """True, and the kind's period starts now, if ``kind`` was not logged within it."""
        now_s = time.monotonic()
        if now_s - self._logged_s[kind] < self._period_s:
            return False
        self._logged_s[kind] = now_s
        return True


def _cut(text: str) -> str:
    """``text`` for the log: at most LOGGED_TEXT_CHARS, with its length when cut."""
    if len(text) <= LOGGED_TEXT_CHARS:
        return text
    return f"{text[:LOGGED_TEXT_CHARS]}... ({len(text)} characters)"


def _descriptor(spec: ParameterSpec) -> ParameterDescriptor:
    constraints = "one of: " + ", ".join(spec.choices) if spec.choices else ""
    descriptor = ParameterDescriptor(
        description=spec.description,
        additional_constraints=constraints
        or ("read-only" if spec.read_only else "applied at configure"),
        read_only=spec.read_only,
    )
    if spec.bounds is not None:
        low, high = spec.bounds
        if isinstance(spec.default, float):
            descriptor.floating_point_range = [FloatingPointRange(from_value=low, to_value=high)]
        else:
            descriptor.integer_range = [IntegerRange(from_value=int(low), to_value=int(high))]
    return descriptor


class _Pending:
    """Samples received since the last batch (plain lists: cheap to append at 1 kHz)."""

    def __init__(self) -> None:
        self.columns: tuple[list[float], ...] = ([], [], [], [])
        self.received = 0

    def add(
        self, stamp_s: float, current_a: float, speed_rad_s: float, position_rad: float
    ) -> None:
        stamps, currents, speeds, positions = self.columns
        stamps.append(stamp_s)
        currents.append(current_a)
        speeds.append(speed_rad_s)
        positions.append(position_rad)
        self.received += 1

    def take(self) -> tuple[MotorSamples, int]:
        """The pending samples (may be empty) and the messages received, then reset."""
        samples = MotorSamples(*(np.asarray(column, dtype=np.float64) for column in self.columns))
        received = self.received
        self.columns, self.received = ([], [], [], []), 0
        return samples, received


class HealthNode(LifecycleNode):
    """The lifecycle node (module docstring)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self._guard_transitions()
        self._declare_errors = self._declare_parameters() | self._unknown_overrides()
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._config: NodeConfig | None = None
        self._estimator: HealthEstimator | None = None
        self._store: StateStore | None = None
        self._persistence = PersistenceHealth(state_file="")
        self._health_pub: Any = None
        self._diagnostics_pub: Any = None
        self._reset_service: Any = None
        self._subscription: Any = None
        self._timers: list[Any] = []
        # Why the last configure failed, and its own /diagnostics publisher and timer (the
        # lifecycle publisher exists only once configured); None after a successful one.
        self._configure_failure: DiagnosticStatusData | None = None
        self._configure_failure_pub: Any = None
        self._configure_failure_timer: Any = None
        self._latest: HealthState | None = None  # the newest estimate
        # The newest estimate is the one restored with the state file (no new one came yet).
        self._latest_restored = False
        self.finalized = False  # shut down (rclpy refuses a second shutdown transition)
        self._reset_run_state()

    # --- parameters ---------------------------------------------------------------------
    def _declare_parameters(self) -> dict[str, str]:
        """Declare every parameter; a value ROS refuses (type, range) is kept as an error for
        configure to report, and the default is declared instead: the node does not crash."""
        errors = {}
        for spec in PARAMETERS:
            try:
                self.declare_parameter(spec.name, spec.default, _descriptor(spec))
            except (InvalidParameterTypeException, InvalidParameterValueException) as exc:
                errors[spec.name] = f"refused by ROS: {str(exc).removesuffix(f': {spec.name}')}"
                self.declare_parameter(
                    spec.name, spec.default, _descriptor(spec), ignore_override=True
                )
        return errors

    def _unknown_overrides(self) -> dict[str, str]:
        """Values given at start (``-p``, a params file) for parameters nobody declared: a
        misspelt name would otherwise leave the default in place without a word. (rclpy keeps
        the overrides only in Node._parameter_overrides.)"""
        errors = {}
        for name in self._parameter_overrides:
            if not self.has_parameter(name):
                close = get_close_matches(name, SPECS, n=1)
                errors[name] = "unknown parameter" + (
                    f" (did you mean {close[0]}?)" if close else ""
                )
        return errors

    def _guard_transitions(self) -> None:
        """Answer a lifecycle transition id the current state does not have with success=False.

        rclpy 7.1 (Jazzy) raises RCLError out of the executor for it, which ends the node and
        loses its unsaved state (ros2/rclpy#1209; fixed upstream by ros2/rclpy#1319, not in
        this release). An unknown label is already answered with success=False."""
        service = self._service_change_state
        change_state = service.callback

        def guarded(request: Any, response: Any) -> Any:
            transition = request.transition
            available = {t[0] for t in self._state_machine.available_transitions}
            if not transition.label and transition.id not in available:
                self.get_logger().warning(
                    f"lifecycle transition {transition.id} refused: not available in state "
                    f"{self._state_machine.current_state[1]}"
                )
                response.success = False
                return response
            return change_state(request, response)

        service.callback = guarded

    def _on_set_parameters(self, parameters: list[Parameter]) -> SetParametersResult:
        # rclpy's use_sim_time too: the diagnostics' clock, every age would jump under a
        # running node.
        for parameter in parameters:
            if self._config is not None and parameter.name in APPLIED_AT_CONFIGURE:
                return SetParametersResult(
                    successful=False,
                    reason=f"parameter {parameter.name} is applied at configure: deactivate"
                    " and clean up the node first",
                )
        ours = [p for p in parameters if p.name in SPECS]
        for parameter in ours:
            if problem := SPECS[parameter.name].problem(parameter.value):
                return SetParametersResult(
                    successful=False, reason=f"parameter {parameter.name}: {problem}"
                )
        # Only once the whole (possibly atomic) set is accepted: a refused set keeps the
        # errors of the values ROS refused at start for configure to report.
        for parameter in ours:
            self._declare_errors.pop(parameter.name, None)
        return SetParametersResult(successful=True)

    def _parameter_values(self) -> dict[str, Any]:
        return {spec.name: self.get_parameter(spec.name).value for spec in PARAMETERS}

    @property
    def save_failed(self) -> bool:
        """The last attempt to save the state failed (the exit code says so at the end)."""
        return self._persistence.save_error is not None

    # --- lifecycle ----------------------------------------------------------------------
    def autostart(self) -> None:
        """Configure and activate if the ``autostart`` parameter says so."""
        if not self.get_parameter("autostart").value:
            self.get_logger().info("autostart is false: waiting for the lifecycle transitions")
            return
        if self.trigger_configure() == TransitionCallbackReturn.SUCCESS:
            self.trigger_activate()

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        values = self._parameter_values()
        try:
            config = node_config(values, self._declare_errors)
        except ConfigError as exc:  # under the hardware_id as given: what a monitor asks for
            return self._configure_failed(str(exc), str(values["hardware_id"]))
        try:
            topic = self.resolve_topic_name(config.input_topic)
        except Exception as exc:  # the expanded name is checked by rcl only
            return self._configure_failed(f"parameter input_topic: {exc}", config.hardware_id)
        try:
            self._configure(config)
        except Exception as exc:
            self._release()
            return self._configure_failed(repr(exc), config.hardware_id)
        self._end_configure_failure()
        self.get_logger().info(
            f"configured: {config.hardware_id}, preset {config.estimator.actuator.preset.name},"
            f" input {config.input_type} on {topic}"
        )
        return TransitionCallbackReturn.SUCCESS

    def _configure_failed(self, reason: str, hardware_id: str) -> TransitionCallbackReturn:
        """Log why configure failed and report it on /diagnostics every
        :data:`CONFIGURE_FAILED_PERIOD_S` until a configure succeeds: the node stays
        unconfigured and publishes nothing else, so that without this a monitor could not
        tell it from a node that is not running. ``hardware_id``: the parameter's, valid or
        not."""
        self.get_logger().error(f"configure failed: {reason}")
        self._configure_failure = configuration_status(reason, hardware_id)
        if self._configure_failure_timer is None:
            self._configure_failure_pub = self.create_publisher(
                DiagnosticArray, "/diagnostics", DIAGNOSTICS_QOS
            )
            self._configure_failure_timer = self.create_timer(
                CONFIGURE_FAILED_PERIOD_S, self._on_configure_failure, clock=self._steady
            )
        return TransitionCallbackReturn.FAILURE

    def _on_configure_failure(self) -> None:
        try:
            if self._configure_failure is not None:
                array = diagnostic_array([self._configure_failure], self._now_s())
                self._configure_failure_pub.publish(array)
        except Exception as exc:
            self.fault("diagnostics", exc)

    def _end_configure_failure(self) -> None:
        """Stop reporting a failed configure (one succeeded, or the node shuts down)."""
        if self._configure_failure_timer is not None:
            self.destroy_timer(self._configure_failure_timer)
            self.destroy_publisher(self._configure_failure_pub)
        self._configure_failure = None
        self._configure_failure_pub = self._configure_failure_timer = None

    def _configure(self, config: NodeConfig) -> None:
        self._reset_run_state()
        if config.input_type == "joint_state":  # stable diagnostics keys from the start
            self._node_rejects.update(dict.fromkeys(JOINT_PROBLEMS, 0))
        estimator = HealthEstimator(config.estimator)
        store = StateStore(config.state_file, config.hardware_id)
        outcome = store.restore(estimator)
        self._persistence = PersistenceHealth(
            state_file=str(config.state_file),
            restored=outcome.restored,
            kept_aside=str(outcome.kept_aside) if outcome.kept_aside else None,
            problem=outcome.problem,
        )
        if outcome.kept_aside is not None:
            estimator = HealthEstimator(config.estimator)  # fresh: restore may have failed late
            self.get_logger().error(
                f"{outcome.problem}; kept as {outcome.kept_aside}; starting fresh"
            )
        elif outcome.restored:
            self.get_logger().info(f"resumed from {config.state_file}")
            if outcome.problem:
                self.get_logger().warning(outcome.problem)
            # The diagnostics report it until the first new estimate (it is not published on
            # ~/health: it is no new estimate).
            self._latest = outcome.last_estimate
            self._latest_restored = self._latest is not None
        else:
            self.get_logger().info(f"no state file at {config.state_file}: starting fresh")
        self._config, self._estimator, self._store = config, estimator, store
        # Counts restored with the state are no input of this run.
        self._tracker.inputs.start_from(
            estimator.counters.accepted, rejected_by_reason(estimator.counters, self._node_rejects)
        )
        self._health_pub = self.create_lifecycle_publisher(
            HealthEstimate, "~/health", HEALTH_QOS_DEPTH
        )
        self._diagnostics_pub = self.create_lifecycle_publisher(
            DiagnosticArray, "/diagnostics", DIAGNOSTICS_QOS
        )
        self._reset_service = self.create_service(
            ResetAfterMaintenance,
            "~/reset_after_maintenance",
            self._on_reset,
            qos_profile=RESET_SERVICE_QOS,
        )

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        config = self._config
        if config is None:  # the lifecycle activates only configured nodes
            return TransitionCallbackReturn.FAILURE
        # Reliable input keeps every sample (KEEP_ALL: a full queue holds the publisher back;
        # KEEP_LAST would overwrite samples that DDS has already acknowledged).
        if config.input_qos == "reliable":
            history, reliability = QoSHistoryPolicy.KEEP_ALL, QoSReliabilityPolicy.RELIABLE
        else:
            history, reliability = QoSHistoryPolicy.KEEP_LAST, QoSReliabilityPolicy.BEST_EFFORT
        qos = QoSProfile(depth=config.input_queue_depth, history=history, reliability=reliability)
        if config.input_type == "motor_state":
            self._subscription = self.create_subscription(
                MotorState, config.input_topic, self._on_input, qos
            )
        else:
            self._subscription = self.create_subscription(
                JointState, config.input_topic, self._on_input, qos
            )
        self._tracker.inputs.topic = self._subscription.topic_name  # resolved: /ns/motor_state
        self._timers = [
            self.create_timer(config.batch_period_s, self._on_batch, clock=self._steady),
            self.create_timer(1.0 / config.diagnostics_rate_hz, self._on_diagnostics),
            self.create_timer(config.save_period_s, self._on_save, clock=self._steady),
        ]
        if config.health_rate_hz > 0.0:
            self._timers.append(
                self.create_timer(1.0 / config.health_rate_hz, self._on_health_timer)
            )
        return super().on_activate(state)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._stop(end_of_data=False)  # activate continues with the same estimator
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._release()
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._stop()
        self._release()
        self._end_configure_failure()
        self.finalized = True
        return TransitionCallbackReturn.SUCCESS

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.get_logger().error(f"error in state {state.label}: releasing and going unconfigured")
        self._stop()
        self._release()
        return TransitionCallbackReturn.SUCCESS

    def _stop(self, *, end_of_data: bool = True) -> None:
        """Process what was received, the last unfinished block included (the input ends
        here; ``end_of_data`` False: it may go on after a reactivation,
        :meth:`HealthEstimator.finish`), save, unsubscribe and stop the timers."""
        if self._subscription is not None:
            self._on_batch(final=True, end_of_data=end_of_data)
            self.destroy_subscription(self._subscription)
            self._subscription = None
        for timer in self._timers:
            self.destroy_timer(timer)
        self._timers = []
        self._save()
        if self._store is not None and self._persistence.save_error is None:
            self.get_logger().info(f"inputs stopped; the state is saved in {self._store.path}")

    def _release(self) -> None:
        """Drop what configure created."""
        for publisher in (self._health_pub, self._diagnostics_pub):
            if publisher is not None:
                self.destroy_lifecycle_publisher(publisher)
        self._health_pub = self._diagnostics_pub = None
        if self._reset_service is not None:
            self.destroy_service(self._reset_service)
            self._reset_service = None
        self._config = self._estimator = self._store = None

    def _reset_run_state(self) -> None:
        self._pending = _Pending()
        self._node_rejects: Counter[str] = Counter()
        self._reject_log = LogThrottle(REJECT_LOG_PERIOD_S)
        self._fault_log = LogThrottle(FAULT_LOG_PERIOD_S)
        self._tracker = DiagnosticsTracker()
        self._latest, self._latest_restored = None, False
        self._latest_published = True
        self._frame_id = ""
        self._saved_at_samples = -1
        self._input_at_steady_s = -math.inf

    # --- inputs -------------------------------------------------------------------------
    def _now_s(self) -> float:
        return float(self.get_clock().now().nanoseconds) / NS_PER_S

    def _on_input(self, msg: Any) -> None:
        try:
            config = self._config
            if config is None:
                return
            sample = input_sample(msg, config.joint_name, config.effort_torque_constant_nm_per_a)
            if sample.problem:
                self._node_rejects[sample.problem] += 1
                self._pending.received += 1
                if self._reject_log.due(sample.problem):
                    self.get_logger().warning(
                        f"JointState rejected ({sample.problem}): joint_name "
                        f"{config.joint_name!r}, the message has {_cut(repr(list(msg.name)))}"
                        f" with {len(msg.effort)} efforts, {len(msg.velocity)} velocities,"
                        f" {len(msg.position)} positions"
                    )
                return
            self._pending.add(
                sample.stamp_s, sample.current_a, sample.speed_rad_s, sample.position_rad
            )
            self._frame_id = msg.header.frame_id
        except Exception as exc:
            self.fault(f"{type(msg).__name__} input", exc)

    def fault(self, where: str, exc: BaseException) -> None:
        """Count and log an exception caught around ``where`` (the filter-consistency status
        names the latest; the log, at most once per FAULT_LOG_PERIOD_S for each place)."""
        events = self._tracker.events
        events.error(self._now_s(), f"{where}: {exc!r}")
        if self._fault_log.due(where):
            self.get_logger().error(f"{where}: {exc!r} ({events.processing_errors} errors so far)")

    # --- processing and outputs ---------------------------------------------------------
    def _on_batch(self, *, final: bool = False, end_of_data: bool = False) -> None:
        """Estimate the samples received since the last batch. When the input has stopped
        for ``diagnostics.stale_timeout_s`` (steady clock: sim time stops with a bag), or
        ``final``, the samples of the last, unfinished block are estimated too
        (:meth:`HealthEstimator.finish`, ``end_of_data`` passed on; nothing once they are): a
        stream that ends loses nothing, and its last estimate does not wait for input to
        resume."""
        try:
            estimator, config = self._estimator, self._config
            if estimator is None or config is None:
                return
            samples, received = self._pending.take()
            now_s = float(self._steady.now().nanoseconds) / NS_PER_S
            if received:
                self._input_at_steady_s = now_s
            states = estimator.process(samples) if len(samples) else []
            silent_s = now_s - self._input_at_steady_s
            if final or silent_s > estimator.params.diagnostics.stale_timeout_s:
                states += estimator.finish(end_of_data=end_of_data)
            self._handle_estimates(estimator, config, states, received)
        except Exception as exc:
            self.fault("processing", exc)

    def _handle_estimates(
        self,
        estimator: HealthEstimator,
        config: NodeConfig,
        states: list[HealthState],
        received: int,
    ) -> None:
        """Track the inputs and events of new estimates and publish them (or keep the newest
        for the health timer)."""
        now = self._now_s()
        counters = estimator.counters
        rejected = rejected_by_reason(counters, self._node_rejects)
        self._tracker.inputs.update(
            now, received, counters.accepted, rejected, estimator.input_clock_s
        )
        self._tracker.events.observe(now, states, counters)
        if states:
            self._latest, self._latest_restored = states[-1], False
            self._latest_published = False
            if config.health_rate_hz == 0.0:
                for state in states:
                    self._publish_health(state)

    def _publish_health(self, state: HealthState) -> None:
        replaced: Counter[str] = Counter()
        fields = health_estimate_fields(state, replaced=replaced)
        self._tracker.events.non_finite(self._now_s(), replaced)
        self._health_pub.publish(health_estimate(fields, state.stamp_s, self._frame_id))
        self._latest_published = True

    def _on_health_timer(self) -> None:
        try:
            if self._latest is not None and not self._latest_published:
                self._publish_health(self._latest)
        except Exception as exc:
            self.fault("health", exc)

    def _on_diagnostics(self) -> None:
        try:
            config, estimator = self._config, self._estimator
            if config is None or estimator is None:
                return
            now = self._now_s()
            # Read here, once per publication: the four medians behind them cost 15 us a read
            # (measured on sudden-jam), which were spent on every input batch.
            self._tracker.inputs.measures = estimator.input_measures
            statuses = self._tracker.statuses(
                self._latest, config.estimator, config.hardware_id, now
            )
            if self._latest_restored and self._latest is not None:
                statuses = restored_statuses(statuses, self._latest.stamp_s)
            statuses.append(persistence_status(self._persistence, config.hardware_id, now))
            self._diagnostics_pub.publish(diagnostic_array(statuses, now))
        except Exception as exc:
            self.fault("diagnostics", exc)

    def _on_reset(self, request: Any, response: Any) -> Any:
        """``~/reset_after_maintenance``: the samples received so far are estimated first
        (they belong to before the maintenance), then the estimator is reset
        (:meth:`HealthEstimator.reset_after_maintenance`) and the state saved at once. The
        reset state (:meth:`HealthEstimator.current_state`, at the last estimate's stamp) is
        handled as the newest estimate, so the health topic and the diagnostics show it
        without waiting for new input."""
        try:
            estimator, config = self._estimator, self._config
            if estimator is None or config is None:  # the service exists only while configured
                raise RuntimeError("the node is not configured")
            self._on_batch()
            before = estimator.reset_after_maintenance(
                request.jammed_rollers,
                reset_precision_loss=request.reset_precision_loss,
                reset_fatigue_damage=request.reset_fatigue_damage,
            )
            # After a restart without input since, the saved estimate brought up to the reset.
            restored = self._latest if self._latest_restored else None
            reset_state = estimator.current_state(restored)  # None: no estimate at all yet
            after = [reset_state] if reset_state is not None else []
            self._handle_estimates(estimator, config, before + after, 0)
            reset = [f"jammed rollers {request.jammed_rollers}"]
            reset += ["precision loss 0"] if request.reset_precision_loss else []
            reset += ["fatigue damage 0"] if request.reset_fatigue_damage else []
            response.success = True
            response.message = "reset after maintenance: " + ", ".join(reset)
            self.get_logger().info(f"{response.message} (note: {_cut(request.note)!r})")
            self._saved_at_samples = -1  # changed without new samples: a failed save is retried
            self._save()
        except ValueError as exc:
            response.success, response.message = False, f"nothing reset: {exc}"
        except Exception as exc:
            self.fault("reset", exc)
            response.success, response.message = False, f"nothing reset: {exc!r}"
        return response

    def _on_save(self) -> None:
        try:
            self._save()
        except Exception as exc:
            self.fault("save", exc)

    def _save(self) -> None:
        """Save the state if samples came since the last successful save, or a reset cleared
        ``_saved_at_samples`` (errors reported, not raised: the next call tries again)."""
        estimator, store = self._estimator, self._store
        if estimator is None or store is None:
            return
        samples = estimator.counters.accepted + estimator.counters.rejected_total
        if samples == self._saved_at_samples:
            return
        try:
            store.save(estimator, self._latest)
        except (OSError, ValueError) as exc:  # ValueError: a value JSON cannot hold
            self._persistence = dataclasses.replace(self._persistence, save_error=str(exc))
            self.get_logger().error(f"cannot save the state: {exc}", throttle_duration_sec=1.0)
            return
        self._saved_at_samples = samples
        self._persistence = dataclasses.replace(
            self._persistence,
            last_save_s=self._now_s(),
            saves=self._persistence.saves + 1,
            save_error=None,
        )


def main(argv: Sequence[str] | None = None) -> int:
    """Run the node until SIGINT/SIGTERM; then shut it down with the state saved."""
    args = list(sys.argv if argv is None else argv)
    try:
        extra = remove_ros_args(args)[1:]
    except _rclpy.RCLError as exc:  # malformed --ros-args (rcl's message spans several lines)
        print(f"prsm-health-node: invalid --ros-args: {str(exc).splitlines()[0]}", file=sys.stderr)
        return 2
    except _rclpy.UnknownROSArgsError as exc:  # e.g. --ros-args --garbage; str: the list
        print(f"prsm-health-node: invalid --ros-args: unknown ROS arguments {exc}", file=sys.stderr)
        return 2
    if extra in (["--help"], ["-h"]):
        print(usage())
        return 0
    if extra:
        print(
            f"prsm-health-node: unexpected arguments {extra}; parameters go after --ros-args,"
            " e.g. --ros-args -p hardware_id:=left",
            file=sys.stderr,
        )
        return 2
    with ros_session(args, ignore_signals_after=True) as stop:
        node = HealthNode()
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        try:
            node.autostart()
            while not stop.is_set() and ok():
                try:
                    executor.spin_once(timeout_sec=SPIN_TIMEOUT_S)
                except ExternalShutdownException:
                    raise
                except Exception as exc:
                    # A callback of rclpy's own raised on a malformed message (a negative
                    # /clock, a parameter of an unknown type): that message is lost, the node
                    # and its state are not.
                    node.fault("a ROS callback", exc)
            if not node.finalized:  # a lifecycle shutdown may have come over its services
                node.trigger_shutdown()
        finally:
            executor.shutdown()
            node.destroy_node()
    return 1 if node.save_failed else 0


if __name__ == "__main__":
    sys.exit(main())
