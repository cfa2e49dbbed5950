"""The experiment runner: loads and validates an experiment (every table, before any stage
runs), then runs its kind's stages into a run folder, each stage completed atomically and
skipped on a rerun when its inputs did not change.

A run folder holds ``experiment.json`` (the validated experiment), one sub-folder per stage
(filled in ``.<stage>.mitpiv-tmp-<lock token>`` and renamed into place with its completion record
``stage.json``: the stage key, its wall time, its result and every output file with its
SHA-256 and size), and at the end ``metrics.json`` (the kind's summary) and
``timings.json`` (seconds per stage), each written once and atomically.

Stage keys (content keys): a stage's key hashes the experiment tables it reads (with every
default filled in), the content (SHA-256) of every file outside the run folder that it
reads (the scene XML and the files that it names), the output checksums of the earlier
stages, the previous stage's key, the mitpiv version, and for stages that render the
Mitsuba and Dr.Jit versions (read from the installed packages' metadata, without importing
them). So an edited scene file, a changed setting or a changed upstream output reruns that
stage and every stage after it, and nothing else.

A stage counts as done only when its completion record lists its outputs and every one of
them is there with its checksum: a stage folder with a missing or corrupt output reruns.

One run at a time: the run folder is locked for the whole run
(:func:`mitpiv.io.atomic.folder_lock`); a second run on it fails at once naming the PID,
host and start time of the holder. Temporary files and stage folders that an interrupted
run left behind are removed when the next run starts (under the lock): only names of
mitpiv's own shapes (:mod:`mitpiv.io.atomic`), never a user's hidden files.

Timings are kept in memory and written once; a skipped stage reports the time it took when
it ran.

Experiment kinds (:mod:`mitpiv.studies.kinds`) plug in by declaring their schema, their
stages (functions of a :class:`~mitpiv.studies.shared.StageContext`: inputs from earlier
stage folders, outputs into their own folder, a JSON result; the files they read and the
packages that shape their output), their summary and their report
(:class:`~mitpiv.studies.shared.Kind`).
"""

from __future__ import annotations

import functools
import hashlib
import json
import logging
import os
import shutil
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from pydantic import BaseModel

from mitpiv.errors import ConfigError
from mitpiv.progress import Progress, bar
from mitpiv.studies.schema import apply_overrides, read_toml, validate
from mitpiv.studies.shared import Kind, Stage, StageContext

__all__ = ["Stage", "StageContext", "RunResult", "Kind", "load_experiment", "run_experiment", "run_config",
           "run_stages", "check_experiment", "content_hash", "experiment_key", "stage_outputs", "SCHEMA_VERSION"]

log = logging.getLogger(__name__)

#: Part of every stage key: raise it when a change makes earlier stage folders invalid.
SCHEMA_VERSION = 3

#: The run's summary files: removed as soon as a stage (re)runs, written when all are done.
SUMMARY_FILES = ("metrics.json", "timings.json")


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
    """Validate an experiment without running it (``mitpiv run --check``): its tables,
    every stage's own check (:func:`preflight`) for a whole run, and the checks that need
    the scene's cameras (each stage's ``scene_check``: the measurement volume in every
    camera's view) or the laser sheet too (each stage's ``rig_check``: the sheet within each
    camera's depth of field), with the scene's sensors and sheets loaded once
    (:func:`~mitpiv.studies.shared.scene_rig`)."""
    from mitpiv.studies.kinds import get_kind
    from mitpiv.studies.shared import scene_rig

    cfg = load_experiment(path, overrides)
    stages = get_kind(cfg.kind).stages(cfg)
    preflight(cfg, stages)
    deep = [s for s in stages if s.scene_check is not None or s.rig_check is not None]
    if deep:
        rig = scene_rig(cfg)
        for s in deep:  # the checks that may refuse first, then those that only warn
            if s.scene_check is not None:
                s.scene_check(cfg, rig.cameras)
        for s in deep:
            if s.rig_check is not None:
                s.rig_check(cfg, rig)
    return cfg


def preflight(cfg: BaseModel, stages) -> None:
    """Run the ``check`` of every stage about to run (:class:`~mitpiv.studies.shared.Stage`),
    before the first of them starts: what a stage cannot do is refused before anything is
    rendered."""
    for s in stages:
        if s.check is not None:
            s.check(cfg)


# ------------------------------------------------------------------------------ stages
def content_hash(obj, *, length: int = 16) -> str:
    """A short hex SHA-256 of a JSON-ready object (keys sorted): stage keys, sweep point ids."""
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()[:length]


@functools.cache
def package_version(name: str) -> str:
    """An installed distribution's version from its metadata (no import), or "not installed"."""
    from importlib import metadata

    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return "not installed"


def _file_digests(paths, cache: dict) -> dict[str, str]:
    from mitpiv.io.records import file_sha256

    out = {}
    for p in paths or ():
        p = Path(p)
        k = str(p)
        if k not in cache:
            cache[k] = file_sha256(p) if p.is_file() else "missing"
        out[k] = cache[k]
    return out


def _static_part(cfg: BaseModel, data: dict, st: Stage, cache: dict) -> dict:
    """What a stage's key holds besides the run's own history: its settings, the content of
    the files it reads and the versions of the code that makes its output."""
    from mitpiv.version import __version__

    return {"stage": st.name, "settings": {t: data.get(t) for t in st.reads},
            "files": _file_digests(st.files(cfg) if st.files is not None else (), cache),
            "mitpiv": __version__, "packages": {n: package_version(n) for n in st.packages}}


def experiment_key(cfg: BaseModel) -> str:
    """The content key of a whole experiment: its resolved settings, the content of every
    input file its stages read and the code versions (mitpiv, and Mitsuba/Dr.Jit where it
    renders). Sweeps key their points on it: a changed base experiment or scene file
    reruns them."""
    from mitpiv.studies.kinds import get_kind

    data = cfg.model_dump(mode="json")
    cache: dict = {}
    parts = [_static_part(cfg, data, st, cache) for st in get_kind(cfg.kind).stages(cfg)]
    return content_hash([f"v{SCHEMA_VERSION}", data, parts])


def _record(stage_dir: Path) -> dict | None:
    from mitpiv.io.records import read_json

    f = stage_dir / "stage.json"
    if not f.is_file():
        return None
    try:
        rec = read_json(f)
    except Exception:  # noqa: BLE001 - an unreadable record is an incomplete stage
        return None
    return rec if isinstance(rec, dict) else None


def stage_outputs(folder, *, fsync: bool = False) -> dict[str, dict]:
    """Every file under a stage folder but its completion record: ``{relative path:
    {"sha256": hex, "bytes": size}}`` (read in a stream; ``fsync``: also flush each to disk)."""
    from mitpiv.io.records import file_sha256

    folder = Path(folder)
    out = {}
    for f in sorted(p for p in folder.rglob("*") if p.is_file()):
        rel = f.relative_to(folder).as_posix()
        if rel == "stage.json":
            continue
        if fsync:
            fd = os.open(f, os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
        out[rel] = {"sha256": file_sha256(f), "bytes": f.stat().st_size}
    return out


def _verified(stage_dir: Path, key: str, name: str, run_name: str) -> dict | None:
    """The completion record of a finished stage with this key whose outputs are all there
    with their checksums; None (the stage reruns) otherwise, with the reason logged."""
    from mitpiv.io.records import file_sha256

    rec = _record(stage_dir)
    if rec is None:
        if stage_dir.exists():
            log.info("[%s] %s: the folder has no readable completion record; the stage reruns", run_name, name)
        return None
    if rec.get("key") != key:
        return None
    outputs = rec.get("outputs")
    if not isinstance(outputs, dict):
        log.info("[%s] %s: its completion record lists no outputs (an older run); the stage reruns", run_name, name)
        return None
    for rel, info in outputs.items():
        f = stage_dir / rel
        try:
            ok = f.is_file() and f.stat().st_size == info["bytes"] and file_sha256(f) == info["sha256"]
        except (OSError, KeyError, TypeError):
            ok = False
        if not ok:
            log.warning("[%s] %s: output %s is %s; the stage reruns", run_name, name, rel,
                        "missing" if not f.is_file() else "changed or corrupt (checksum differs)")
            return None
    return rec


def _clean(run: Path, stages: list[Stage], token: str) -> None:
    """Remove what an interrupted run left: temporary stage folders and files (not those of
    the current holder, ``token``)."""
    from mitpiv.io.atomic import clean_temps

    clean_temps(run, token=token)
    for st in stages:
        clean_temps(run / st.name, token=token)


def run_stages(cfg: BaseModel, run_dir, stages: list[Stage], *, progress: Progress = None
               ) -> tuple[dict[str, dict], dict[str, float]]:
    """Run (or skip) each stage of ``stages`` into the run folder; returns (results, timings)
    per stage. See the module notes for keys, records, locking and atomic completion.

    Raises :class:`~mitpiv.errors.FolderLockedError` when another process is running in
    ``run_dir``.
    """
    from mitpiv._alloc import retain_freed_memory
    from mitpiv.io.atomic import folder_lock, fsync_dir, temp_dir
    from mitpiv.io.records import write_json

    retain_freed_memory()  # large temporaries reuse freed pages (mitpiv._alloc: demo 48.7 -> 41.0 s)
    run = Path(run_dir)
    with folder_lock(run, what="run folder") as token:
        _clean(run, stages, token)
        data = cfg.model_dump(mode="json")
        write_json(run / "experiment.json", data)
        name = data.get("name", "experiment")
        results: dict[str, dict] = {}
        timings: dict[str, float] = {}
        upstream: dict[str, str] = {}
        cache: dict = {}
        prev = f"v{SCHEMA_VERSION}:{data.get('kind')}"
        with bar(len(stages), desc=f"{name}", progress=progress, unit="stage") as b:
            for st in stages:
                prev = content_hash({"prev": prev, **_static_part(cfg, data, st, cache), "upstream": upstream})
                final, tmp = run / st.name, temp_dir(run, st.name)
                b.set_description(f"{name}: {st.name}")
                rec = _verified(final, prev, st.name, name)
                if rec is not None:
                    log.info("[%s] %s: done earlier, skipped", name, st.name)
                    results[st.name] = rec.get("result") or {}
                    timings[st.name] = float(rec.get("seconds", 0.0))
                    upstream[st.name] = content_hash(rec["outputs"])
                    b.update()
                    continue
                log.info("[%s] %s ...", name, st.name)
                for f in SUMMARY_FILES:  # an earlier run's summary no longer describes this folder
                    (run / f).unlink(missing_ok=True)
                tmp.mkdir()  # named for this holder alone (its lock token): never there before
                t0 = time.perf_counter()
                try:
                    ctx = StageContext(cfg=cfg, run_dir=run, out=tmp, results=results, timings=timings,
                                       progress=progress)
                    result = st.run(ctx) or {}
                    seconds = time.perf_counter() - t0
                    outputs = stage_outputs(tmp, fsync=True)
                    write_json(tmp / "stage.json", {"key": prev, "seconds": seconds, "result": result,
                                                    "outputs": outputs})
                    fsync_dir(tmp)
                except BaseException:
                    shutil.rmtree(tmp, ignore_errors=True)
                    raise
                old = temp_dir(run, st.name, "old")
                shutil.rmtree(old, ignore_errors=True)
                if final.exists():
                    os.replace(final, old)
                os.replace(tmp, final)
                fsync_dir(run)
                shutil.rmtree(old, ignore_errors=True)
                # the result exactly as a rerun reads it back (JSON types)
                results[st.name] = _record(final)["result"]
                timings[st.name] = seconds
                upstream[st.name] = content_hash(outputs)
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
    preflight(cfg, stages)
    from mitpiv.io.atomic import folder_lock

    with folder_lock(run, what="run folder"):
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

    Each stage is skipped when its folder holds a verified completion record with the same
    content key (the settings that reach it, the content of the files it reads, the earlier
    stages' outputs, the code versions); a changed setting or input file reruns that stage
    and the ones after it. The same seed gives the same metrics.
    """
    return run_config(load_experiment(path, overrides), out_dir, until=until, progress=progress)
