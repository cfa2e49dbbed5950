"""The experiment runner: loads and validates an experiment (every table, before any stage
runs), then runs its kind's stages into a run folder, each stage completed atomically and
skipped on a rerun when its inputs did not change.

A run folder holds ``experiment.json`` (the validated experiment), one sub-folder per stage
(filled in ``.<stage>.tmp`` and renamed into place with its completion record
``stage.json``: the stage key, its wall time and its result), and at the end
``metrics.json`` (the kind's summary) and ``timings.json`` (seconds per stage), each written
once and atomically.

Stage keys: a stage's key hashes the experiment tables it reads (with every default filled
in) and the previous stage's key, so a changed setting reruns that stage and every stage
after it. Timings are kept in memory and written once; a skipped stage reports the time it
took when it ran.

Experiment kinds (:mod:`mitpiv.studies.kinds`) plug in by declaring their schema, their
stages (functions of a :class:`StageContext`: inputs from earlier stage folders, outputs
into their own folder, a JSON result), their summary and their report.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import shutil
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

from pydantic import BaseModel

from mitpiv.errors import ConfigError
from mitpiv.progress import Progress, bar
from mitpiv.studies.schema import apply_overrides, read_toml, validate

__all__ = ["Stage", "StageContext", "RunResult", "Kind", "load_experiment", "run_experiment", "run_config",
           "run_stages", "check_experiment", "content_hash", "SCHEMA_VERSION"]

log = logging.getLogger(__name__)

#: Part of every stage key: raise it when a change makes earlier stage folders invalid.
SCHEMA_VERSION = 2


@dataclass(frozen=True)
class Stage:
    """One stage of an experiment kind.

    name : the stage folder's name.
    reads : the experiment's top-level keys (tables) whose values reach this stage.
    run : ``run(ctx) -> dict``: fills ``ctx.out`` and returns a JSON-ready result.
    """

    name: str
    reads: tuple[str, ...]
    run: Callable[[StageContext], dict | None]


@dataclass
class StageContext:
    """What a stage sees: the experiment, where earlier stages wrote, where it writes."""

    cfg: BaseModel
    run_dir: Path
    out: Path
    results: dict[str, dict]
    timings: dict[str, float]
    progress: Progress = None

    def input(self, stage: str, name: str) -> Path:
        """The file ``name`` that the earlier stage ``stage`` wrote."""
        return self.run_dir / stage / name


@dataclass(frozen=True)
class Kind:
    """An experiment kind: its schema, stages, summary (metrics.json) and sweep-table row."""

    name: str
    build_schema: Callable[[], type[BaseModel]]
    stages: Callable[[BaseModel], list[Stage]]
    summary: Callable[[BaseModel, dict], dict]
    row: Callable[[dict], dict]
    describe: str = ""
    headline: Callable[[dict], str] | None = None
    aliases: tuple[str, ...] = ()
    prepare: Callable[[dict, Path], dict] | None = None

    @property
    def schema(self) -> type[BaseModel]:
        """The kind's experiment model (one frozen pydantic model, a field per TOML table)."""
        return self.build_schema()


@dataclass
class RunResult:
    """The outcome of a run: the kind's summary (``metrics``), the seconds per stage and the
    per-stage results. ``result["piv"]`` and ``result.get("evaluate")`` read the summary."""

    name: str
    kind: str
    run_dir: Path
    metrics: dict
    timings: dict
    stages: dict = field(default_factory=dict)

    def __getitem__(self, key):
        return self.metrics[key]

    def get(self, key, default=None):
        return self.metrics.get(key, default)

    def __contains__(self, key) -> bool:
        return key in self.metrics

    def headline(self) -> str:
        """One line: the run's main numbers."""
        from mitpiv.studies.kinds import get_kind

        k = get_kind(self.kind)
        return k.headline(self.metrics) if k.headline else f"{self.name}: done"

    def row(self) -> dict:
        """The flat table row a sweep records: the kind's metric columns and the timings."""
        from mitpiv.studies.kinds import get_kind

        out = dict(get_kind(self.kind).row(self.metrics))
        out.update({f"seconds.{k}": v for k, v in self.timings.items()})
        out["seconds.total"] = float(sum(self.timings.values()))
        return out


# ------------------------------------------------------------------------------ loading
def load_experiment(path, overrides: Mapping | None = None) -> BaseModel:
    """Read an experiment TOML file, apply dotted-key ``overrides``, and validate every
    table against its kind's schema; returns the frozen experiment model (paths absolute).

    Raises :class:`ConfigError` naming the table, the key, the bad value and the valid
    choices, before anything runs.
    """
    from mitpiv.studies.kinds import get_kind

    path = Path(path)
    raw = apply_overrides(read_toml(path), overrides)
    raw.setdefault("name", path.stem)
    kind = get_kind(raw.get("kind", "tomo"), source=f"experiment {path}")
    raw["kind"] = kind.name
    if kind.prepare is not None:
        raw = kind.prepare(raw, path.parent)
    return validate(kind.schema, raw, source=f"experiment {path}")


def check_experiment(path, overrides: Mapping | None = None) -> BaseModel:
    """Validate an experiment without running it (``mitpiv run --check``)."""
    return load_experiment(path, overrides)


# ------------------------------------------------------------------------------ stages
def content_hash(obj, *, length: int = 16) -> str:
    """A short hex SHA-256 of a JSON-ready object (keys sorted): stage keys, sweep point ids."""
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()[:length]


def _record(stage_dir: Path) -> dict | None:
    from mitpiv.io.records import read_json

    f = stage_dir / "stage.json"
    if not f.is_file():
        return None
    try:
        return read_json(f)
    except Exception:  # noqa: BLE001 - an unreadable record is an incomplete stage
        return None


def run_stages(cfg: BaseModel, run_dir, stages: list[Stage], *, progress: Progress = None
               ) -> tuple[dict[str, dict], dict[str, float]]:
    """Run (or skip) each stage of ``stages`` into the run folder; returns (results, timings)
    per stage. See the module notes for keys, records and atomic completion."""
    from mitpiv.io.records import write_json

    run = Path(run_dir)
    run.mkdir(parents=True, exist_ok=True)
    data = cfg.model_dump(mode="json")
    write_json(run / "experiment.json", data)
    name = data.get("name", "experiment")
    results: dict[str, dict] = {}
    timings: dict[str, float] = {}
    prev = f"v{SCHEMA_VERSION}:{data.get('kind')}"
    with bar(len(stages), desc=f"{name}", progress=progress, unit="stage") as b:
        for st in stages:
            prev = content_hash([prev] + [data.get(t) for t in st.reads])
            final, tmp = run / st.name, run / f".{st.name}.tmp"
            rec = _record(final)
            b.set_description(f"{name}: {st.name}")
            if rec is not None and rec.get("key") == prev:
                log.info("[%s] %s: done earlier, skipped", name, st.name)
                results[st.name] = rec.get("result") or {}
                timings[st.name] = float(rec.get("seconds", 0.0))
                b.update()
                continue
            log.info("[%s] %s ...", name, st.name)
            shutil.rmtree(tmp, ignore_errors=True)
            tmp.mkdir(parents=True)
            t0 = time.perf_counter()
            try:
                ctx = StageContext(cfg=cfg, run_dir=run, out=tmp, results=results, timings=timings,
                                   progress=progress)
                result = st.run(ctx) or {}
                seconds = time.perf_counter() - t0
                write_json(tmp / "stage.json", {"key": prev, "seconds": seconds, "result": result})
            except BaseException:
                shutil.rmtree(tmp, ignore_errors=True)
                raise
            old = run / f".{st.name}.old"
            shutil.rmtree(old, ignore_errors=True)
            if final.exists():
                os.replace(final, old)
            os.replace(tmp, final)
            shutil.rmtree(old, ignore_errors=True)
            # the result exactly as a rerun reads it back (JSON types)
            results[st.name] = _record(final)["result"]
            timings[st.name] = seconds
            log.info("[%s] %s: %.1f s", name, st.name, seconds)
            b.update()
    return results, timings


def run_config(cfg: BaseModel, out_dir, *, until: str | None = None, progress: Progress = None) -> RunResult:
    """Run (or resume) an already validated experiment into ``out_dir``.

    until : the name of the last stage to run (e.g. ``"render"``); the result then holds
        the stages' results but no summary, and ``metrics.json`` is not written.
    """
    from mitpiv.io.records import write_json
    from mitpiv.studies.kinds import get_kind

    if not isinstance(cfg, BaseModel):
        raise ConfigError("run_config: give the experiment returned by load_experiment (a validated model), "
                          f"got {type(cfg).__name__}.")
    kind = get_kind(cfg.kind)
    run = Path(out_dir)
    stages = kind.stages(cfg)
    if until is not None:
        names = [s.name for s in stages]
        if until not in names:
            raise ConfigError(f"run: until={until!r} is not a stage of this {kind.name} experiment; its stages are "
                              f"{names}.")
        stages = stages[:names.index(until) + 1]
    results, timings = run_stages(cfg, run, stages, progress=progress)
    if until is not None:
        return RunResult(name=cfg.name, kind=kind.name, run_dir=run, metrics={}, timings=timings, stages=results)
    summary = kind.summary(cfg, results)
    write_json(run / "metrics.json", summary)
    write_json(run / "timings.json", timings)
    return RunResult(name=cfg.name, kind=kind.name, run_dir=run, metrics=summary, timings=timings, stages=results)


def run_experiment(path, out_dir, *, overrides: Mapping | None = None, until: str | None = None,
                   progress: Progress = None) -> RunResult:
    """Run (or resume) the experiment in ``path`` into ``out_dir``; returns its :class:`RunResult`.

    Each stage is skipped when its folder holds a completion record with the same inputs
    (the experiment's settings that reach it); a changed setting reruns that stage and the
    ones after it. The same seed gives the same metrics.
    """
    return run_config(load_experiment(path, overrides), out_dir, until=until, progress=progress)
