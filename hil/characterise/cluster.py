"""A population calibrated on a Dask distributed cluster (``characterise --scheduler
tcp://HOST:8786``), for populations that outgrow one machine.

Why Dask distributed and not Ray: each unit is one independent task that runs a command
and writes its certificate. Dask's futures do exactly that from a pure-Python package
(``pip install 'gimbal-hil[cluster]'``) on the clusters people already run (``dask
scheduler`` and ``dask worker`` over SSH, dask-jobqueue on SLURM or PBS, Kubernetes).
Ray would bring its own runtime and object store, a wheel many times the size, for
features this work does not use.

What the workers need: this project installed (the same version), and ``--out`` and the
profiles at the same paths as here (a shared file system): every unit's certificate is
written there, and read back here. The result does not depend on where a unit ran: each
has its own seed and its own process.
"""

from __future__ import annotations

import socket
from collections.abc import Callable, Sequence
from typing import Any
from urllib.parse import urlsplit

from hil.characterise.draw import Unit
from hil.errors import InputError

#: how long to wait for the scheduler before giving up
CONNECT_TIMEOUT_S = 10.0

Results = dict[str, dict[str, Any]]


def map_on_cluster(address: str, calibrate: Callable[[Unit], Results], units: Sequence[Unit],
                   progress: Callable[[Unit, Results], None]) -> list[Results]:
    """``calibrate(unit)`` for every unit on the cluster at ``address``.

    Parameters
    ----------
    address : str
        The Dask scheduler (``tcp://HOST:8786``).
    calibrate : callable
        A module-level function (or a ``functools.partial`` of one), so that a worker can
        import it.
    units : sequence of Unit
    progress : callable
        Called here with each unit and its results as it ends (in the order they end).

    Returns
    -------
    list
        Each unit's results, in the units' order.

    Raises
    ------
    InputError
        Dask distributed is not installed, or the scheduler cannot be reached.
    """
    try:
        from distributed import Client, as_completed
    except ImportError:
        raise InputError("needs Dask distributed: pip install 'gimbal-hil[cluster]'",
                         source="--scheduler") from None
    _refuse_a_closed_port(address)
    try:
        client = Client(address, timeout=f"{CONNECT_TIMEOUT_S}s")  # type: ignore[no-untyped-call]
    except ValueError as exc:  # not an address (no port, unknown protocol)
        raise InputError(f"not a scheduler address (tcp://HOST:PORT): {exc}",
                         source="--scheduler") from None
    except (OSError, TimeoutError) as exc:
        raise InputError(f"cannot reach the Dask scheduler at {address}: {exc}",
                         source="--scheduler") from None
    with client:
        futures = client.map(calibrate, list(units), pure=False)
        index = {future.key: i for i, future in enumerate(futures)}
        done: list[Results | None] = [None] * len(futures)
        for future in as_completed(futures):  # type: ignore[no-untyped-call]
            i = index[future.key]
            done[i] = future.result()
            progress(units[i], done[i] or {})
    return [results or {} for results in done]


def _refuse_a_closed_port(address: str) -> None:
    """Refuse a ``tcp://HOST:PORT`` address that takes no connection, at once when nothing
    listens there (Dask's client retries a refused connection until its timeout), else
    within :data:`CONNECT_TIMEOUT_S`; other addresses are left to Dask."""
    try:
        parts = urlsplit(address)
        host, port = parts.hostname, parts.port
    except ValueError:
        return
    if parts.scheme != "tcp" or host is None or port is None:
        return
    try:
        socket.create_connection((host, port), timeout=CONNECT_TIMEOUT_S).close()
    except ConnectionRefusedError:
        raise InputError(f"cannot reach the Dask scheduler at {address}: nothing listens "
                         "there (connection refused)", source="--scheduler") from None
    except OSError as exc:  # unresolved, unreachable, no answer within the timeout
        raise InputError(f"cannot reach the Dask scheduler at {address}: {exc}",
                         source="--scheduler") from None
