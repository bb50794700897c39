"""The Ray engine: connect to a cluster (or start a local one) and run the runs there.

``--ray`` alone: connect to the Ray instance running on this machine (started with
``ray start --head``), or start a private one with ``--workers`` CPUs when there is
none (and stop it at the end). ``--ray ADDRESS``: the cluster's GCS address
``HOST:PORT`` (``ray start --head`` prints it; port 6379 when left out), or
``ray://HOST:PORT`` through Ray's client (port 10001 when left out; needs
``ray[client]``, which the ``cluster`` extra installs).

Connecting never hangs: the address is first tried as a plain TCP connection
(:data:`REACH_TIMEOUT`), and Ray's own handshake (which retries for a long time on
its own) is given until ``deadline`` (:data:`CONNECT_DEADLINE` unless told; a
ray:// client starts a server process per driver, which takes tens of seconds on a
busy machine) after the start; past it the
command says so in one line and exits with :data:`EXIT_CLUSTER`. Ray's messages
while connecting are kept out of the terminal; the one that explains a failure
(a missing or wrong token) is turned into the error line.

Token authentication (Ray >= 2.5x): a cluster started with ``RAY_AUTH_MODE=token``
accepts only drivers that present its token. Set ``RAY_AUTH_MODE=token`` and give the
token as ``RAY_AUTH_TOKEN``, in a file named by ``RAY_AUTH_TOKEN_PATH``, or in
``~/.ray/auth_token`` (``ray get-auth-token`` prints a cluster's token on its head
node). With bare ``--ray`` Ray itself switches token mode on when a token file
exists; a private local instance started by ``--ray`` uses a token that Ray
generates into ``~/.ray/auth_token``.
"""

from __future__ import annotations

import contextlib
import logging
import os
import socket
import sys
import tempfile
import threading
from collections.abc import Callable, Generator, Iterator
from dataclasses import dataclass
from typing import Any

from ..errors import EXIT_CLUSTER, ClusterError
from .spec import Spec

REACH_TIMEOUT = 5.0  # s for the plain TCP check of an address
CONNECT_DEADLINE = 60.0  # s from the start of connecting to giving up (default)
POLL = 0.25  # s between two looks at the stop request while waiting for rows
CLIENT_PORT, GCS_PORT = 10001, 6379

AUTH_HINT = (
    "the cluster uses token authentication: export RAY_AUTH_MODE=token and give its "
    "token as RAY_AUTH_TOKEN, in the file named by RAY_AUTH_TOKEN_PATH or in "
    "~/.ray/auth_token (`ray get-auth-token` on the head node prints it)"
)


@dataclass
class Connection:
    """Where the runs go: the address joined, and whether the instance is ours to stop."""

    address: str
    started_here: bool
    initialized_here: bool
    cpus: float


def _import_ray() -> Any:
    try:
        import ray
    except ImportError:
        raise ClusterError(
            "--ray: Ray is not installed; install the cluster extra: "
            "pip install 'dftc-mujoco[cluster]' (or pip install -e '.[cluster]' in a clone)"
        ) from None
    return ray


def host_port(address: str) -> tuple[str, int]:
    """The host and port of a GCS (``HOST[:PORT]``) or client (``ray://HOST[:PORT]``)
    address, or a ClusterError saying what is wrong with it."""
    client = address.startswith("ray://")
    rest = address.removeprefix("ray://").rstrip("/")
    host, sep, port = rest.rpartition(":") if ":" in rest else (rest, "", "")
    if not sep:
        host, port = rest, str(CLIENT_PORT if client else GCS_PORT)
    host = host.strip("[]")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise ClusterError(
            f"--ray {address}: expected HOST:PORT (a Ray GCS address, as `ray start --head` "
            "prints it) or ray://HOST:PORT (Ray's client)"
        )
    return host, int(port)


def reachable(address: str, timeout: float = REACH_TIMEOUT) -> None:
    """A ClusterError unless a TCP connection to ``address`` opens within ``timeout``."""
    host, port = host_port(address)
    try:
        with socket.create_connection((host, port), timeout=timeout):
            pass
    except TimeoutError:
        raise ClusterError(
            f"--ray {address}: no answer from {host}:{port} within {timeout:g} s; is the "
            "address right and is `ray start --head` running there?"
        ) from None
    except OSError as exc:
        reason = exc.strerror or str(exc)
        raise ClusterError(
            f"--ray {address}: cannot reach {host}:{port} ({reason}); is the address right "
            "and is `ray start --head` running there?"
        ) from None


def _local_instances(ray: Any) -> tuple[list[str], str | None]:
    """Live GCS addresses on this machine, and the one ``ray start`` recorded last."""
    try:
        from ray._private import services, utils

        live = sorted(services.find_gcs_addresses())
        latest = utils.read_ray_address(None)
    except Exception:  # private API: without it, let ray.init(address="auto") decide
        return [], None
    return live, latest


@contextlib.contextmanager
def _quiet_stderr() -> Iterator[Callable[[], str]]:
    """Inside, what is written to file descriptor 2 (Ray's C++ core logs there) goes to
    a temporary file; yields a function that returns it."""
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile(mode="w+b") as tmp:
        os.dup2(tmp.fileno(), 2)

        def text() -> str:
            tmp.seek(0)
            return tmp.read().decode(errors="replace")

        try:
            yield text
        finally:
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)


def _give_up(fd: int, message: str) -> None:
    """Print ``error: message`` on file descriptor ``fd`` and end the process with
    EXIT_CLUSTER: Ray's connect cannot be interrupted, and a half-made connection must
    not hang the interpreter's exit either."""
    os.write(fd, f"error: {message}\n".encode())
    os._exit(EXIT_CLUSTER)


def connect(address: str | None, workers: int, deadline: float = CONNECT_DEADLINE) -> Connection:
    """Join the cluster at ``address`` (None: the local instance, or a new private one).

    Raises ClusterError (one line) when Ray is missing or the cluster cannot be joined;
    exits the process with EXIT_CLUSTER when joining takes longer than ``deadline``
    seconds.
    """
    ray = _import_ray()
    if ray.is_initialized():  # the caller already joined a cluster (the Python API)
        return Connection("(already initialised)", False, False, _cpus(ray))
    env = os.environ.get("RAY_ADDRESS")
    if address in (None, "", "auto") and env:
        address = env
    start = False
    if address in (None, "", "auto"):
        live, latest = _local_instances(ray)
        if len(live) > 1 and latest not in live:
            raise ClusterError(
                f"--ray: several Ray instances run on this machine ({', '.join(live)}); "
                "choose one with --ray ADDRESS"
            )
        start = not live
        target = "local" if start else "auto"
    else:
        if address.startswith("ray://"):
            try:
                import grpc  # noqa: F401 - ray:// needs Ray's client (grpcio)
            except ImportError:
                raise ClusterError(
                    f"--ray {address}: ray:// addresses need Ray's client: "
                    "pip install 'ray[client]' (the cluster extra installs it)"
                ) from None
        reachable(address)
        target = address
    kwargs: dict[str, Any] = {
        "include_dashboard": False,
        "log_to_driver": False,
        "logging_level": logging.ERROR,
    }
    if start:
        kwargs["num_cpus"] = workers
    shown = "a new local Ray instance" if start else (address or "the local Ray instance")
    real_stderr = os.dup(2)
    message = (
        f"--ray: could not join {shown} within {deadline:g} s (--ray-timeout); check the address, "
        "the cluster's state (`ray status` there) and its token (RAY_AUTH_MODE=token, "
        "RAY_AUTH_TOKEN)"
    )
    timer = threading.Timer(deadline, _give_up, args=(real_stderr, message))
    timer.daemon = True
    timer.start()
    try:
        with _quiet_stderr() as said:
            try:
                ray.init(address=target, **kwargs)
            except Exception as exc:
                raise ClusterError(_explain(shown, exc, said())) from None
    finally:
        timer.cancel()
        os.close(real_stderr)
    info = ray.get_runtime_context()
    joined = getattr(info, "gcs_address", None) or address or "local"
    return Connection(str(joined), start, True, _cpus(ray))


def _cpus(ray: Any) -> float:
    try:
        return float(ray.cluster_resources().get("CPU", 0.0))
    except Exception:
        return 0.0


def _explain(shown: str, exc: BaseException, said: str) -> str:
    """One line for a failed ray.init, from its exception and what Ray logged meanwhile."""
    text = f"{exc}\n{said}"
    if (
        "InvalidAuthToken" in text
        or "AuthenticationError" in type(exc).__name__
        or ("authentication" in text.lower() and "token" in text.lower())
    ):
        return f"--ray: cannot join {shown}: {AUTH_HINT}"
    first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    if "Initialization failure from server" in first:  # Ray's client server, on the head
        first += (
            " (the head's Ray client server did not start this driver's server in time, as on"
            " a loaded head: try again, or run the campaign on the head with --ray auto)"
        )
    return f"--ray: cannot join {shown}: {first}"


def disconnect(conn: Connection) -> None:
    """Leave the cluster (and stop the private instance started for this campaign)."""
    if not conn.initialized_here:
        return
    import ray

    if ray.is_initialized():
        with _quiet_stderr():
            ray.shutdown()


@dataclass
class RayRuns:
    """The runs of ``spec`` as Ray tasks; ``stop()`` True cancels what is not finished."""

    spec: Spec
    stop: Callable[[], bool] = lambda: False
    cancelled: int = 0

    def rows(self, todo: list[dict[str, Any]]) -> Generator[dict[str, Any], None, None]:
        """The rows of the runs ``todo``, in the order they finish."""
        import ray

        from .task import run_one

        remote = ray.remote(num_cpus=1)(run_one)
        spec_ref = ray.put(self.spec)
        pending = [remote.remote(spec_ref, p) for p in todo]
        try:
            while pending and not self.stop():
                ready, pending = ray.wait(pending, num_returns=1, timeout=POLL)
                for ref in ready:
                    yield ray.get(ref)
        finally:
            self.cancelled = len(pending)
            for ref in pending:
                with contextlib.suppress(Exception):
                    ray.cancel(ref, force=True)
