"""The results of a batch: ``DIR/summary.json`` and ``DIR/summary.csv``, both written atomically.

``summary.json``::

    {"engine": "ray", "ray_version": "2.60.0", "pscc_version": "0.1.0", "sweep": "/abs/sweep.toml",
     "cluster": "a local Ray instance with 2 workers", "devices": "cpu", "status": "done",
     "counts": {"done": 4, "failed": 0, "pending": 0, "interrupted": 0},
     "runs": [{"id": "drape-friction=0.1", "scene": "drape", "out_dir": "runs/drape-friction=0.1",
               "values": {"cloth.material.friction": 0.1}, "status": "done", "error": null, "frames": 2,
               "seconds_per_frame": 0.12, "intersecting_frames": 0, "halvings": 0, "resumed_from": null,
               "ran": true, "device": "cpu", "host": "node-1"}, ...]}

``summary.csv`` has one row per run with the same fields, one column per varied key path (numbers and
strings as they are, booleans and arrays as JSON). The batch's ``status`` is ``running`` while it
runs, then ``done``, ``failed`` (some run failed) or ``interrupted``.
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path
from typing import Any

from pscc._atomic import write_json_atomic, write_text_atomic
from pscc.batch.sweep import Run, Sweep

__all__ = ["RUN_STATUSES", "SUMMARY_CSV", "SUMMARY_JSON", "pending_record", "summary", "write_summary"]

SUMMARY_JSON = "summary.json"
SUMMARY_CSV = "summary.csv"
RUNS_FOLDER = "runs"
"""``DIR/runs/<run id>/`` is each run's folder."""

RUN_STATUSES: tuple[str, ...] = ("done", "failed", "pending", "interrupted")
"""A run's ``status``: finished, failed (with its ``error``), not finished yet, or stopped with the batch."""

_RESULT_FIELDS: tuple[str, ...] = ("frames", "seconds_per_frame", "intersecting_frames", "halvings", "resumed_from",
                                   "ran", "device", "host", "error")


def pending_record(status: str = "pending", error: str | None = None) -> dict[str, Any]:
    """The record of a run that has no result (yet): ``pending``, ``interrupted``, or ``failed`` with ``error``."""
    return {"status": status, "error": error, "frames": 0, "seconds_per_frame": None, "intersecting_frames": 0,
            "halvings": 0, "resumed_from": None, "ran": False, "device": None, "host": None}


def summary(sweep: Sweep, runs: list[Run], results: dict[str, dict[str, Any]], *, status: str, cluster: str,
            devices: str, ray_version: str) -> dict[str, Any]:
    """The ``summary.json`` object: one record per run, in sweep order (``results`` by run id)."""
    from pscc import __version__

    records = []
    for run in runs:
        result = results.get(run.run_id) or pending_record()
        records.append({"id": run.run_id, "scene": run.scene, "out_dir": f"{RUNS_FOLDER}/{run.run_id}",
                        "values": run.values, **result})
    counts = {name: sum(1 for r in records if r["status"] == name) for name in RUN_STATUSES}
    return {"engine": "ray", "ray_version": ray_version, "pscc_version": __version__, "sweep": str(sweep.path),
            "cluster": cluster, "devices": devices, "status": status, "counts": counts, "runs": records}


def _cell(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, str):
        return value
    if isinstance(value, float):
        return repr(value)
    return json.dumps(value)


def write_summary(out_dir: Path, data: dict[str, Any]) -> None:
    """Write ``summary.json`` and ``summary.csv`` into ``out_dir`` (atomically, JSON first).

    Raises:
        OutputError: a file cannot be written.
    """
    write_json_atomic(out_dir / SUMMARY_JSON, data, field="--out-dir")
    keys = list(dict.fromkeys(key for record in data["runs"] for key in record["values"]))
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["id", "scene", "status", "out_dir", *keys, *_RESULT_FIELDS])
    for record in data["runs"]:
        writer.writerow([record["id"], record["scene"], record["status"], record["out_dir"],
                         *(_cell(record["values"].get(key)) for key in keys),
                         *(_cell(record.get(name)) for name in _RESULT_FIELDS)])
    write_text_atomic(out_dir / SUMMARY_CSV, buffer.getvalue(), field="--out-dir")
