"""Run every run of a sweep as a Ray task (``pscc batch``): on a local Ray instance or an existing cluster.

:func:`run_batch` checks the sweep and every run before anything starts, connects to Ray, submits one
task per run that is not done (:func:`pscc.batch.task.run_task`, one CPU, or one GPU and one CPU),
collects the small records the tasks return while a progress bar counts finished runs, and writes
``DIR/summary.json`` and ``DIR/summary.csv`` (:mod:`pscc.batch.summary`). Frames never travel through
Ray: each task writes its run folder ``DIR/runs/<run id>/`` itself, so on a cluster ``DIR`` must be a
file system that every node sees at the same path (docs/batch.md).

Faults:

* a task whose worker dies (killed, out of memory, a crash in native code) is started again by Ray
  (``max_retries`` of the sweep) and resumes from the run's last checkpoint;
* a run that fails on its own (a :class:`~pscc.errors.PsccError`, a bug) is recorded as ``failed``
  with its error and is not retried; the other runs go on; the batch then ends with an
  :class:`~pscc.errors.InputError` naming the failed runs (exit status 2);
* ``--resume`` runs only the runs whose folders are not done (see :func:`pscc.batch.task.finished`);
* Ctrl-C (or SIGTERM) cancels the tasks, which record ``interrupted`` and keep their checkpoints,
  writes the summary of what finished, shuts a local instance down and re-raises.
"""

from __future__ import annotations

import fcntl
import json
import logging
import os
import signal
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from pscc.batch.summary import RUNS_FOLDER, SUMMARY_JSON, pending_record, summary, write_summary
from pscc.batch.sweep import Run, Sweep, expand_runs, load_sweep
from pscc.batch.task import finished, run_record, run_task
from pscc.errors import InputError, one_line

__all__ = ["DEVICES", "run_batch"]

DEVICES: tuple[str, ...] = ("cpu", "cuda")
"""Values of ``--devices``: what each task asks Ray for and simulates on."""

SUMMARY_INTERVAL = 10.0
"""Seconds between rewrites of the summary while the batch runs (and once at the end)."""

CANCEL_GRACE = 15.0
"""Seconds a cancelled batch waits for its tasks to record ``interrupted`` before it lets them go."""

BATCH_LOCK = ".pscc-batch.lock"
"""``DIR/.pscc-batch.lock``: held by the process running a batch in ``DIR``."""

INSTALL_FIX = 'install Ray with pip install "pscc[batch]" (Ray 2.60.0 with its client), then run again'


def _import_ray() -> Any:
    try:
        import ray
    except ImportError:
        raise InputError("argument", "batch", "Ray is not installed", INSTALL_FIX) from None
    return ray


def _check_out_dir(out_dir: Path, resume: bool) -> None:
    """Refuse an ``--out-dir`` that is not a folder, or holds a batch when not resuming."""
    if not str(out_dir).strip():
        raise InputError(repr(str(out_dir)), "--out-dir", "is empty", "name a folder for the batch")
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError(str(out_dir), "--out-dir", "exists and is not a folder", "pick another --out-dir")
    runs = out_dir / RUNS_FOLDER
    held = (out_dir / SUMMARY_JSON).exists() or (runs.is_dir() and any(runs.iterdir()))
    if held and not resume:
        raise InputError(str(out_dir), "--out-dir", "already holds a batch (summary.json or runs/)",
                         "pass --resume to continue it (only the runs not done are run), or pick another --out-dir")


@contextmanager
def _batch_lock(out_dir: Path) -> Iterator[None]:
    """Hold ``DIR/.pscc-batch.lock`` (one batch per folder at a time)."""
    path = out_dir / BATCH_LOCK
    handle = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            owner = os.pread(handle, 32, 0).decode(errors="replace").strip()
            raise InputError(str(out_dir), "--out-dir", f"another pscc batch{f' (pid {owner})' if owner else ''} "
                             "is running in this folder", "wait for it to finish, or pick another --out-dir") from None
        os.ftruncate(handle, 0)
        os.write(handle, f"{os.getpid()}\n".encode())
        yield
    finally:
        try:
            os.unlink(path)
        except OSError:
            pass
        os.close(handle)


CONNECT_TIMEOUT = 10.0
"""Seconds to wait for a cluster's port to answer before ``ray.init`` is called (Ray itself retries for minutes)."""


def _check_reachable(address: str) -> None:
    """Refuse an ``--address`` whose host and port do not answer (``auto``: the cluster Ray would find)."""
    import socket

    target: str | None = address
    if address == "auto":
        try:
            from ray._private.services import canonicalize_bootstrap_address
        except ImportError:  # another Ray version: ray.init reports the problem itself
            return
        try:
            target = canonicalize_bootstrap_address("auto")
        except Exception:
            return
        if target is None:  # no cluster known here: ray.init says so at once
            return
    host, _, port = target.removeprefix("ray://").rpartition(":")
    if not host or not port.isdigit():
        return
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=CONNECT_TIMEOUT).close()
    except OSError as error:
        found = f" (the cluster auto found: {target})" if address == "auto" else ""
        raise InputError("argument", "--address", f"nothing answers at {address}{found} ({error.strerror or error})",
                         "start the cluster first (ray start --head) or check the address and that its port is "
                         "reachable from here") from None


class _Connection:
    """Ray for one batch: a local instance started for it, a cluster connected to, or this process's own.

    Args:
        workers: CPUs of a local instance (``None``: this machine's cores).
        address: ``auto``, ``host:port`` or ``ray://host:port`` of an existing cluster (``None``: local).
    """

    def __init__(self, ray: Any, workers: int | None, address: str | None) -> None:
        self.ray = ray
        self.owned = False
        if ray.is_initialized():
            if address is not None or workers is not None:
                raise InputError("argument", "--address", "this process is connected to Ray already",
                                 "leave out --address and --workers (the batch uses the open connection)")
            self.description = "the Ray connection of this process"
            return
        sigterm = signal.getsignal(signal.SIGTERM)
        try:
            if address is None:
                count = workers or os.cpu_count() or 1
                ray.init(address="local", num_cpus=count, include_dashboard=False, log_to_driver=False,
                         logging_level=logging.ERROR)
                self.description = f"a local Ray instance with {count} worker{'s' if count != 1 else ''}"
            else:
                _check_reachable(address)
                ray.init(address=address, log_to_driver=False, logging_level=logging.ERROR)
                self.description = f"the Ray cluster at {address}"
        except InputError:
            raise
        except ImportError as error:
            raise InputError("argument", "--address", f"Ray cannot connect to {address} here ({one_line(error)})",
                             INSTALL_FIX) from None
        except (ConnectionError, RuntimeError, ValueError, TimeoutError) as error:
            if ray.is_initialized():
                ray.shutdown()
            if address is None:
                raise InputError("argument", "--workers", f"Ray could not start a local instance ({one_line(error)})",
                                 "see Ray's logs in /tmp/ray/session_latest/logs") from None
            raise InputError("argument", "--address", f"Ray could not connect to {address} ({one_line(error)})",
                             "check the address (ray status on the cluster prints it); a cluster with token "
                             "authentication (Ray's default) needs RAY_AUTH_MODE=token and its token in "
                             "~/.ray/auth_token or RAY_AUTH_TOKEN") from None
        finally:
            if threading.current_thread() is threading.main_thread():
                signal.signal(signal.SIGTERM, sigterm)  # ray.init installs its own; pscc's stops cleanly
        self.owned = True

    def gpus(self) -> float:
        """GPUs of the whole cluster."""
        return float(self.ray.cluster_resources().get("GPU", 0.0))

    def close(self) -> None:
        """Shut a local instance down (never a cluster the batch connected to: disconnect only)."""
        if self.owned and self.ray.is_initialized():
            self.ray.shutdown()
        self.owned = False


def _choose_devices(devices: str | None, gpus: float) -> str:
    if devices is not None and devices not in DEVICES:
        raise InputError("argument", "--devices", f"{devices!r} is not one of {', '.join(DEVICES)}",
                         "pass --devices cpu or --devices cuda")
    if devices is None:
        return "cuda" if gpus >= 1 else "cpu"
    if devices == "cuda" and gpus < 1:
        raise InputError("argument", "--devices", "cuda asks each task for a GPU, but the Ray cluster has none",
                         "pass --devices cpu, or add nodes with GPUs to the cluster")
    return devices


def _collect(ray: Any, ref: Any, folder: Path, retries: int) -> dict[str, Any]:
    """The record of a finished task; a task Ray gave up on is a failed run, a cancelled one ``interrupted``."""
    try:
        return dict(ray.get(ref))
    except ray.exceptions.TaskCancelledError:
        status, error = "interrupted", None
    except (ray.exceptions.WorkerCrashedError, ray.exceptions.NodeDiedError, ray.exceptions.OutOfMemoryError) as exc:
        status, error = "failed", f"its worker died {retries + 1} time(s), the last time: {one_line(exc)}"
    except ray.exceptions.RayError as exc:
        status, error = "failed", f"{type(exc).__name__}: {one_line(exc)}"
    record = run_record(folder, status=status, error=error)
    record["host"] = None  # the worker's name is not known here
    return record


def run_batch(sweep_path: str | os.PathLike[str], out_dir: str | os.PathLike[str], *, workers: int | None = None,
              address: str | None = None, devices: str | None = None, resume: bool = False, progress: bool = True,
              echo: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Run every run of a sweep on Ray; return the summary written to ``out_dir/summary.json``.

    Args:
        sweep_path: the sweep file (docs/batch.md).
        out_dir: the batch folder: ``runs/<run id>/`` per run, ``summary.json``, ``summary.csv``.
        workers: CPUs (concurrent CPU tasks) of the local Ray instance (default: this machine's cores).
        address: an existing cluster (``auto``, ``host:port``, ``ray://host:port``); ``None`` starts a
            local instance, shut down at the end. A process already connected to Ray uses that connection.
        devices: ``cpu`` (each task asks for one CPU) or ``cuda`` (one GPU and one CPU, simulating on
            the worker's ``cuda:0``); ``None``: ``cuda`` when the cluster has GPUs, else ``cpu``.
        resume: continue the batch in ``out_dir``: runs done already are kept, the others run (from
            their checkpoints).
        progress: show a progress bar counting finished runs.
        echo: prints the lines saying what runs where (``None``: silent).

    Raises:
        InputError: a bad sweep or run (before anything is written or started), a folder that holds a
            batch (without ``resume``), Ray missing or unreachable, ``devices`` the cluster lacks; after
            the batch, when some runs failed (the summary names them).
        KeyboardInterrupt: Ctrl-C or SIGTERM; the summary lists what finished (the rest ``interrupted``).
    """
    echo = echo or (lambda line: None)
    sweep: Sweep = load_sweep(sweep_path)
    runs = expand_runs(sweep)
    out = Path(out_dir)
    _check_out_dir(out, resume)
    ray = _import_ray()
    results = _done_runs(out, runs) if resume else {}
    if len(results) == len(runs):  # nothing to run: no Ray instance, no cluster
        out.mkdir(parents=True, exist_ok=True)
        with _batch_lock(out):
            echo(f"pscc batch: all {len(runs)} runs of the sweep are done already")
            data = summary(sweep, runs, results, status="done", cluster="none (every run was done)",
                           devices=_previous(out).get("devices", "none"), ray_version=ray.__version__)
            write_summary(out, data)
            return data
    connection = _Connection(ray, workers, address)
    try:
        chosen = _choose_devices(devices, connection.gpus())
        out.mkdir(parents=True, exist_ok=True)
        with _batch_lock(out):
            return _run(ray, connection, sweep, runs, results, out, chosen, progress, echo)
    finally:
        connection.close()


def _previous(out: Path) -> dict[str, Any]:
    """The batch's last ``summary.json`` (empty when there is none or it cannot be read)."""
    try:
        data = json.loads((out / SUMMARY_JSON).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def _done_runs(out: Path, runs: list[Run]) -> dict[str, dict[str, Any]]:
    """Records of the runs whose folders are done (``--resume`` keeps them), with the host and checkpoint the last
    summary recorded for them."""
    before = {r.get("id"): r for r in _previous(out).get("runs") or [] if isinstance(r, dict)}
    results = {}
    for run in runs:
        folder = out / RUNS_FOLDER / run.run_id
        if finished(folder, run.frames, run.identity):
            record = run_record(folder, status="done", ran=False)
            record.update({k: before[run.run_id].get(k) for k in ("host", "resumed_from") if run.run_id in before})
            results[run.run_id] = record
    return results


def _run(ray: Any, connection: _Connection, sweep: Sweep, runs: list[Run], results: dict[str, dict[str, Any]],
         out: Path, devices: str, progress: bool, echo: Callable[[str], None]) -> dict[str, Any]:
    todo = [run for run in runs if run.run_id not in results]
    scenes = len(sweep.scenes)
    echo(f"pscc batch: {len(runs)} run{'s' if len(runs) != 1 else ''} ({scenes} scene{'s' if scenes != 1 else ''} x "
         f"{sweep.combinations} combination{'s' if sweep.combinations != 1 else ''}) on {connection.description}, "
         f"{devices}, Ray {ray.__version__}" + (f"; {len(runs) - len(todo)} done already" if results else ""))

    def write(status: str) -> dict[str, Any]:
        data = summary(sweep, runs, results, status=status, cluster=connection.description, devices=devices,
                       ray_version=ray.__version__)
        write_summary(out, data)
        return data

    write("running")
    options: dict[str, Any] = {"num_cpus": 1, "max_retries": sweep.max_retries, "retry_exceptions": False}
    if devices == "cuda":
        options.update(num_gpus=1, max_calls=1)  # a fresh worker per task: Warp sees the GPU Ray assigned
    remote = ray.remote(**options)(run_task)
    device = "cuda:0" if devices == "cuda" else "cpu"
    pending = {remote.options(name=f"pscc-batch:{run.run_id}").remote(run, str(out / RUNS_FOLDER / run.run_id),
                                                                      device): run for run in todo}
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(runs), initial=len(runs) - len(todo), unit="run", desc="batch", dynamic_ncols=True)
    written = time.monotonic()
    try:
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1, timeout=1.0)
            for ref in ready:
                run = pending.pop(ref)
                results[run.run_id] = _collect(ray, ref, out / RUNS_FOLDER / run.run_id, sweep.max_retries)
                if bar is not None:
                    failed = sum(1 for r in results.values() if r["status"] == "failed")
                    bar.set_postfix(failed=failed, refresh=False)
                    bar.update(1)
            if time.monotonic() - written > SUMMARY_INTERVAL:
                write("running")
                written = time.monotonic()
    except KeyboardInterrupt as error:
        for ref in pending:
            ray.cancel(ref)  # a KeyboardInterrupt in each task: its folder records "interrupted"
        ready, _ = ray.wait(list(pending), num_returns=len(pending), timeout=CANCEL_GRACE) if pending else ([], [])
        for ref in ready:
            run = pending[ref]
            results[run.run_id] = _collect(ray, ref, out / RUNS_FOLDER / run.run_id, sweep.max_retries)
        for run in pending.values():
            results.setdefault(run.run_id, pending_record("interrupted"))
        data = write("interrupted")
        left = len(runs) - data["counts"]["done"]
        error.add_note(f"{out / SUMMARY_JSON} lists {data['counts']['done']} done run(s); pass --resume to run the "
                       f"other {left} (from their checkpoints)")
        raise
    finally:
        if bar is not None:
            bar.close()
    final = write("failed" if any(r["status"] == "failed" for r in results.values()) else "done")
    failed = [r for r in final["runs"] if r["status"] == "failed"]
    if failed:
        first = failed[0]
        raise InputError(str(out / SUMMARY_JSON), "runs", f"{len(failed)} of {len(runs)} runs failed (the first, "
                         f"{first['id']}: {first['error']})", "summary.json holds each run's error; fix the cause and "
                         "run again with --resume (done runs are kept)")
    return final
