"""Where a campaign's tasks run: Ray (embedded, or a cluster), or local processes.

Both give the driver the same three calls: ``submit(fn, *args) -> handle``, ``wait(handles)``
(the handles that finished, within a short timeout) and ``result(handle)`` (the value, or the
task's exception). A task whose worker dies is run again (``retries`` times): Ray re-runs just
that task; so does the local executor (:mod:`lipgen.campaign.local`), whose workers are
one-process pools given a task only when free.
"""

from __future__ import annotations

import contextlib
import logging
import os
import socket
import time

from lipgen.campaign.local import LocalExecutor
from lipgen.errors import LipgenError

__all__ = ["ClusterError", "RayExecutor", "LocalExecutor", "check_address", "check_executor", "make_executor"]

log = logging.getLogger(__name__)



def _worker_env() -> dict:
    """Environment of every Ray worker: one BLAS thread, GL rasterizing in the rendering thread."""
    from lipgen._threads import POLICY_ENV, RENDER_THREAD_ENV, THREAD_ENV

    env = dict.fromkeys(THREAD_ENV, "1")
    return env if os.environ.get(POLICY_ENV) == "off" else env | RENDER_THREAD_ENV


class ClusterError(LipgenError, ConnectionError):
    """The Ray cluster cannot be reached or started."""


def check_address(address: str, timeout: float = 5.0) -> None:
    """Fail fast (``ClusterError``) when ``host:port`` (or ``ray://host:port``) does not answer.

    ``ray.init`` would otherwise retry for minutes. ``"auto"`` is left to Ray, which fails at
    once when no local cluster runs.
    """
    if address == "auto":
        return
    hostport = address.split("://", 1)[-1]
    host, sep, port = hostport.rpartition(":")
    if not sep or not host or not port.isdigit():
        raise ClusterError(f"--address must look like HOST:PORT, ray://HOST:PORT or auto, got {address!r}")
    try:
        with socket.create_connection((host.strip("[]"), int(port)), timeout=timeout):
            pass
    except OSError as exc:
        raise ClusterError(f"cannot reach the Ray cluster at {address} ({exc.strerror or exc}); is it up "
                           "(ray status on the head node), and is the port open from here?") from None


def _raylet_alive() -> bool | None:
    """Whether a ``raylet`` child of this process runs (None where /proc cannot tell)."""
    me = str(os.getpid())
    try:
        for d in os.scandir("/proc"):
            if d.name.isdigit():
                try:
                    with open(f"/proc/{d.name}/stat") as fh:
                        stat = fh.read()
                except OSError:
                    continue
                name, rest = stat[stat.index("(") + 1:stat.rindex(")")], stat[stat.rindex(")") + 2:]
                if name == "raylet" and rest.split()[1] == me:
                    return True
    except OSError:
        return None
    return False


@contextlib.contextmanager
def _environment(env: dict):
    """Set ``env`` in this process's environment inside the block (then put it back)."""
    old = {k: os.environ.get(k) for k in env}
    os.environ.update(env)
    try:
        yield
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


_PATIENT = {"worker_register_timeout_seconds": 600, "agent_register_timeout_ms": 600_000}
"""The embedded Ray's start-up limits (Ray 2.60's worker default is 60 s): a worker or agent that
imports slowly on a loaded machine is waited for, not killed and started again."""

_QUIET_NODE = {"RAY_enable_metrics_collection": "0", "RAY_USAGE_STATS_ENABLED": "0",
               "RAY_event_stats": "0", "RAY_task_events_report_interval_ms": "0"}
"""Bookkeeping the embedded node skips unless the dashboard is asked for: on 2 cores its metrics,
event stats and task events took the CPU the second worker needed (parallel efficiency 1 -> 2
CPUs, idle machine, same run: 0.78 with them, 0.92 without). A value the user set is kept."""


def _node_env(dashboard: bool) -> dict:
    """The environment the embedded node's processes start with (see ``_QUIET_NODE``)."""
    env = dict(_worker_env())
    if not dashboard:
        env.update({k: os.environ.get(k, v) for k, v in _QUIET_NODE.items()})
    return env


@contextlib.contextmanager
def _patient_node_start(ray, poll: float = 0.2, give_up_s: float = 1800.0):
    """Let an embedded Ray node start however loaded the machine is.

    ``ray.init`` gives the raylet a fixed 30 s (``raylet_start_wait_time_s`` in
    ``ray/_private/node.py``, not configurable) to register with the GCS; the raylet registers
    once its Python agents have imported, which on 2 cores shared with 20-30 busy processes takes
    longer. Inside this block the node's registration check waits for as long as its raylet
    process is alive (so a raylet that died still fails at once), instead of a wall-clock window.
    It only touches the check Ray calls while a local node starts, and puts it back after.
    """
    services = getattr(getattr(ray, "_private", None), "services", None)
    original = getattr(services, "get_node", None)
    if original is None:  # another Ray layout: keep Ray's own window
        yield
        return

    def get_node(gcs_address, node_id):
        t0 = time.monotonic()
        while True:
            try:
                return original(gcs_address, node_id)
            except RuntimeError:
                if _raylet_alive() is False or time.monotonic() - t0 > give_up_s:
                    raise
                time.sleep(poll)

    services.get_node = get_node
    try:
        yield
    finally:
        services.get_node = original


class RayExecutor:
    """Tasks as Ray remote functions; ``address=None`` starts an embedded local Ray."""

    kind = "ray"

    def __init__(self, address: str | None = None, num_cpus: int | None = None, retries: int = 2,
                 dashboard: bool = False) -> None:
        from lipgen._optional import require

        ray = require("ray", "lipgen campaign")
        self.ray, self.retries = ray, retries
        env = {"env_vars": _worker_env()}
        if address is not None:
            check_address(address)
        try:
            if address is None:  # the node's processes inherit the workers' environment from here:
                # with a runtime_env instead, Ray's pre-started workers (default env) sit idle and
                # a second set is started (measured: 14 % more worker CPU with 2 CPUs than with 1)
                with _patient_node_start(ray), _environment(_node_env(dashboard)):
                    ray.init(address="local", num_cpus=num_cpus, include_dashboard=dashboard,
                             log_to_driver=False, configure_logging=False, _system_config=_PATIENT)
            else:
                ray.init(address=address, runtime_env=env, log_to_driver=False, configure_logging=False)
        except Exception as exc:  # noqa: BLE001  (Ray raises bare Exception on a failed start)
            ray.shutdown()
            raise ClusterError(f"could not start or join Ray (address {address or 'local'}): {exc}") from exc
        self._remote: dict = {}
        ctx = ray.get_runtime_context()
        self.dashboard_url = getattr(ctx, "dashboard_url", None) or None
        log.info("Ray: %s, resources %s", address or "embedded local", ray.cluster_resources())

    @property
    def workers(self) -> int:
        return int(self.ray.cluster_resources().get("CPU", 1))

    def put(self, obj):
        """Store ``obj`` once in the object store; tasks given the reference read it there."""
        return self.ray.put(obj)

    def submit(self, fn, *args):
        """Run ``fn(*args)`` as a Ray task (one CPU, re-run if its worker dies); returns its reference."""
        key = fn.__module__ + "." + fn.__qualname__
        if key not in self._remote:
            self._remote[key] = self.ray.remote(num_cpus=1, max_retries=self.retries)(fn)
        return self._remote[key].remote(*args)

    def wait(self, handles, timeout: float = 0.5) -> list:
        """The ``handles`` that finished, waiting at most ``timeout`` seconds."""
        if not handles:
            return []
        done, _ = self.ray.wait(list(handles), num_returns=len(handles), timeout=timeout)
        return done

    def result(self, handle):
        """The task's value, or its own exception raised here."""
        try:
            return self.ray.get(handle)
        except self.ray.exceptions.RayTaskError as exc:  # the task's own exception, as raised there
            cause = exc.as_instanceof_cause()
            raise cause from None

    def shutdown(self) -> None:
        """Disconnect (and stop the embedded Ray)."""
        self.ray.shutdown()


def check_executor(kind: str, address: str | None, workers: int | None) -> None:
    """The checks of :func:`make_executor`'s arguments, made before a campaign writes anything."""
    if kind not in ("ray", "local"):
        raise ValueError(f"executor must be 'ray' or 'local', got {kind!r}")
    if kind == "local" and address is not None:
        raise ValueError("--address needs the ray executor, not --executor local")
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int)
                                or not 1 <= workers <= 256):
        raise ValueError(f"workers must be a whole number in [1, 256], got {workers!r}")


def make_executor(kind: str = "ray", address: str | None = None, workers: int | None = None, retries: int = 2,
                  dashboard: bool = False):
    """A :class:`RayExecutor` (``kind="ray"``) or a :class:`LocalExecutor` (``kind="local"``)."""
    check_executor(kind, address, workers)
    if kind == "ray":
        return RayExecutor(address, workers, retries, dashboard)
    return LocalExecutor(workers or os.cpu_count() or 1, retries)
