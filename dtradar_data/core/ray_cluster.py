"""Connecting to Ray, bounded: one helper for ``build --executor ray`` and ``python -m dtradar_rl sweep``.

``ray.init(address=...)`` with an address where no Ray cluster listens does not fail: it retries for many minutes,
printing ``Failed to connect to GCS`` now and then. So before Ray is asked to connect, :func:`check_ray_address`
resolves the address as ``ray.init`` would (``auto``, ``$RAY_ADDRESS``, ``127.0.0.1`` made this node's address) and
tries its TCP port for :data:`PROBE_TIMEOUT_S`; :func:`connect_ray` then gives ``ray.init`` itself at most
:data:`CONNECT_TIMEOUT_S` (a port that answers but is not a Ray cluster). Both fail with a
:class:`~dtradar_data.core.errors.RayClusterError` that names the address and how to fix it. Ray is imported only
when called, so this module costs nothing without it (it lives in ``core`` so that ``dtradar_rl`` can use it without
the pipeline's tracer).
"""

from __future__ import annotations

import importlib.util
import logging
import os
import socket
import sys
import threading
import time

from dtradar_data.core.errors import InvalidSettingError, MissingDependencyError, RayClusterError

RAY_INSTALL = "pip install 'dtradar[ray]'  (or: pip install 'ray>=2.40')"
RAY_ADDRESS_ENV = "RAY_ADDRESS"
PROBE_TIMEOUT_S = 5.0
"""How long the TCP port of a cluster address may take to accept a connection."""
CONNECT_TIMEOUT_S = 60.0
"""How long ``ray.init`` may take to connect to a cluster whose port answered."""
NODE_WAIT_S = 300.0
"""How long a cluster without a node big enough for one task may take to get one (an autoscaler adding nodes)."""
NOTICE_EVERY_S = 30.0
"""While waiting for such a node, say so again this often."""
INIT_KWARGS = {"include_dashboard": False, "log_to_driver": False, "configure_logging": False}


def import_ray(hint: str = RAY_INSTALL):
    """The ``ray`` module, or :class:`MissingDependencyError` saying how to install it."""
    try:
        import ray
    except ImportError as e:
        raise MissingDependencyError("--executor ray needs Ray, which is not installed", hint=hint) from e
    return ray


def requested_address(address: str | None) -> tuple[str | None, str]:
    """The cluster ``ray.init(address=address)`` connects to, and where that came from: ``$RAY_ADDRESS`` wins over
    nothing and over ``auto`` (as in Ray). ``None`` (or ``local``): Ray starts a local instance."""
    env = os.environ.get(RAY_ADDRESS_ENV, "").strip()
    if env and address in (None, "", "auto"):
        return env, f"${RAY_ADDRESS_ENV}"
    return (address or None), ""


def fix_hint(flag: str, source: str, *, auto: bool = False) -> str:
    drop = f"unset {source[1:]}" if source else f"drop {flag}"
    start = (
        "start one on this machine with `ray start --head`"
        if auto
        else "start a cluster there (`ray start --head` on that machine prints the address to use) or fix the address"
    )
    return f"{start}; or {drop} to run on a local Ray started for this command"


def check_address_given(address: str | None, *, flag: str = "--ray-address", error=InvalidSettingError) -> None:
    """``error`` (an :class:`InvalidSettingError` or a subclass) naming ``flag`` when ``address`` is given but empty
    (``--ray-address ""``): it names an existing cluster, yet Ray would start a local one, as leaving the flag out
    does. Checked with the other settings, before Ray is imported or anything runs."""
    if address is not None and not address.strip():
        raise error(
            f"{flag} {address!r} is empty: it names an existing Ray cluster",
            hint=f"give the cluster's address (auto, HOST:6379 or ray://HOST:10001), or drop {flag} for the default: "
            f"a local Ray on this machine's cores (${RAY_ADDRESS_ENV} when it is set)",
        )


def check_ray_address(address: str | None, *, flag: str = "--ray-address", timeout_s: float = PROBE_TIMEOUT_S):
    """Raise unless something listens at the Ray cluster ``address`` (or ``$RAY_ADDRESS``), within ``timeout_s``.

    Returns the ``(host, port)`` tried, or ``None`` when Ray will start a local instance (nothing to reach).
    :class:`RayClusterError` when nothing answers; :class:`InvalidSettingError` for an address without a port;
    :class:`MissingDependencyError` for ``ray://`` without Ray Client's packages.
    """
    addr, source = requested_address(address)
    if addr is None or addr == "local":
        return None
    named = f"{source}={addr}" if source else f"{flag} {addr}"
    if addr == "auto":
        target = _auto_address(named, flag, source)
        if target is None:
            return None  # this Ray cannot tell: the bounded ray.init of connect_ray still applies
    else:
        scheme, sep, rest = addr.partition("://")
        if not sep:
            scheme, rest = "", addr
        if scheme == "ray" and importlib.util.find_spec("grpc") is None:
            raise MissingDependencyError(
                f"{named}: a ray:// address needs Ray Client, which is not installed",
                hint="pip install 'ray[client]', or give the cluster's HOST:PORT (port 6379) instead",
            )
        target = _host_port(rest.split("/", 1)[0])
        if target is None:
            raise InvalidSettingError(
                f"{named} is not a Ray cluster address (no port)",
                hint="give HOST:PORT (what `ray start --head` prints; port 6379 by default), ray://HOST:10001 "
                "(Ray Client) or auto",
            )
        if not scheme:
            target = _as_ray_connects(addr) or target
    host, port = target
    try:
        socket.create_connection((host, port), timeout=timeout_s).close()
    except OSError as exc:
        reason = f"no answer within {timeout_s:g} s" if isinstance(exc, TimeoutError) else exc.strerror or repr(exc)
        where = f"{host}:{port}" + ("" if addr.endswith(f"{host}:{port}") else f" (where Ray connects for {addr})")
        raise RayClusterError(
            f"{named}: nothing answers at {where}: {reason}; no Ray cluster runs there",
            hint=fix_hint(flag, source, auto=addr == "auto"),
        ) from exc
    return target


def connect_ray(
    ray,
    address: str | None,
    *,
    num_cpus: int | None = None,
    flag: str = "--ray-address",
    timeout_s: float = CONNECT_TIMEOUT_S,
) -> bool:
    """Connect to ``address`` (or ``$RAY_ADDRESS``), or start a local Ray with ``num_cpus`` CPUs (None: all); True
    when this call did (the caller shuts it down), False when Ray was already initialised.

    A cluster must answer within :data:`PROBE_TIMEOUT_S` (its port) and ``timeout_s`` (``ray.init``), else
    :class:`RayClusterError`; one line on stderr says what is being waited for.
    """
    if ray.is_initialized():
        return False
    addr, source = requested_address(address)
    if addr is None or addr == "local":
        ray.init(**({"address": addr} if addr else {}), **({"num_cpus": num_cpus} if num_cpus else {}), **INIT_KWARGS)
        return True
    check_ray_address(address, flag=flag)
    named = f"{source}={addr}" if source else f"{flag} {addr}"
    print(f"connecting to the Ray cluster at {addr} (at most {timeout_s:g} s; Ctrl-C is safe)", file=sys.stderr)
    outcome: dict[str, BaseException | bool] = {}

    def init() -> None:
        try:
            ray.init(address=addr, **INIT_KWARGS)
            outcome["ok"] = True
        except BaseException as exc:  # noqa: BLE001 - handed to the calling thread
            outcome["error"] = exc

    quiet = _DropRecords("SIGTERM handler is not set")  # Ray's note that a thread cannot install signal handlers
    worker_log = logging.getLogger("ray._private.worker")
    worker_log.addFilter(quiet)
    try:
        thread = threading.Thread(target=init, name="ray-connect", daemon=True)
        thread.start()
        thread.join(timeout_s)
    finally:
        worker_log.removeFilter(quiet)
    if thread.is_alive():  # left behind as a daemon: the command fails now instead of hanging
        raise RayClusterError(
            f"{named}: something listens there but no Ray cluster accepted this driver within {timeout_s:g} s",
            hint=fix_hint(flag, source),
        )
    error = outcome.get("error")
    if isinstance(error, BaseException):
        text = _reason(error)
        if "ray[client]" in text:
            raise MissingDependencyError(f"{named}: {text}", hint="pip install 'ray[client]'") from error
        hint = fix_hint(flag, source)
        if "auth" in text.lower():
            hint = "make the cluster's token available here (RAY_AUTH_TOKEN or ~/.ray/auth_token); or " + hint
        raise RayClusterError(f"{named}: Ray could not connect ({text})", hint=hint) from error
    return True


def _reason(error: BaseException, limit: int = 300) -> str:
    """One line: ``error``'s message and, when it wraps another, the last error line of the innermost cause (Ray's
    ``Failed to connect`` hides why: a refused token, another Ray version ...)."""
    text = " ".join(str(error).split())
    root = error
    while root.__cause__ is not None and root.__cause__ is not root:
        root = root.__cause__
    if root is not error:
        lines = [ln.strip() for ln in str(root).splitlines() if ln.strip()]
        errors = [ln for ln in lines if "Error" in ln.split(":", 1)[0]]
        detail = (errors or lines or [type(root).__name__])[-1]
        if detail not in text:
            text += f": {detail}"
    return text if len(text) <= limit else text[: limit - 3] + "..."


def largest_node_cpus(ray) -> float:
    """The CPUs of the cluster's largest live node (a task's CPUs must all be on one node)."""
    return max((n.get("Resources", {}).get("CPU", 0.0) for n in ray.nodes() if n.get("Alive")), default=0.0)


def wait_for_cpus(
    ray,
    need: int,
    *,
    what: str,
    address: str | None = None,
    flag: str = "--ray-address",
    timeout_s: float | None = None,
) -> float:
    """Return the CPUs of the cluster's largest node once it has at least ``need`` (a task asking for more than any
    node has would otherwise wait for ever, silently). A cluster at an address may get nodes (an autoscaler): wait
    for one at most ``timeout_s`` (default :data:`NODE_WAIT_S`), saying so on stderr; a local Ray started for this
    command will not, so it fails at once. :class:`RayClusterError` names the shortfall and how to fix it."""
    addr, source = requested_address(address)
    at = f" at {addr}" if addr and addr != "local" else ""
    limit = (NODE_WAIT_S if timeout_s is None else timeout_s) if at else 0.0
    most = largest_node_cpus(ray)
    if most >= need:
        return most
    start = time.monotonic()
    if limit > 0:
        print(
            f"waiting up to {limit:g} s for the Ray cluster{at} to have a node with {need} CPU(s) for {what} (its "
            f"largest has {most:g}; an autoscaler adds nodes). Ctrl-C is safe",
            file=sys.stderr,
            flush=True,
        )
    notice = start + NOTICE_EVERY_S
    while time.monotonic() - start < limit:
        time.sleep(min(1.0, limit))
        most = largest_node_cpus(ray)
        if most >= need:
            return most
        if time.monotonic() >= notice:
            notice += NOTICE_EVERY_S
            print(f"still waiting for a node with {need} CPU(s) (largest: {most:g})", file=sys.stderr, flush=True)
    joined = f", and none joined within {limit:g} s" if limit > 0 else ""
    raise RayClusterError(
        f"the Ray cluster{at} has no node with {need} CPU(s) for {what} (its largest has {most:g}){joined}",
        hint="add nodes with CPUs (`ray start --address <head>` on them; a head started with --num-cpus 0 runs no "
        "tasks), or ask for fewer CPUs per task; or drop "
        + (f"{flag} to run on a local Ray" if at and not source else "--executor ray"),
    )


class _DropRecords(logging.Filter):
    def __init__(self, prefix: str):
        super().__init__()
        self.prefix = prefix

    def filter(self, record: logging.LogRecord) -> bool:
        return not str(record.msg).startswith(self.prefix)


def _host_port(text: str) -> tuple[str, int] | None:
    host, sep, port = text.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        return None
    return host.strip("[]"), int(port)


def _as_ray_connects(addr: str) -> tuple[str, int] | None:
    """``addr`` as Ray resolves it before connecting (a loopback host becomes this node's address), if this Ray
    says; None otherwise."""
    try:
        from ray._private.services import canonicalize_bootstrap_address

        return _host_port(canonicalize_bootstrap_address(addr) or "")
    except Exception:  # noqa: BLE001 - a private helper of Ray: without it, probe the address as given
        return None


def _auto_address(named: str, flag: str, source: str) -> tuple[str, int] | None:
    """The cluster ``auto`` finds on this machine (the last ``ray start``), or :class:`RayClusterError` if none;
    None when this Ray cannot tell."""
    try:
        from ray._private.services import canonicalize_bootstrap_address_or_die
    except Exception:  # noqa: BLE001 - a private helper of Ray
        return None
    try:
        found = canonicalize_bootstrap_address_or_die("auto")
    except ConnectionError as exc:
        raise RayClusterError(
            f"{named}: no running Ray cluster found on this machine ({' '.join(str(exc).split())})",
            hint=fix_hint(flag, source, auto=True),
        ) from exc
    except Exception:  # noqa: BLE001 - anything else: leave it to the bounded ray.init
        return None
    return _host_port(found or "")
