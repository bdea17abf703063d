"""A batch manifest: the fits of a collection, stated once in YAML.

.. code-block:: yaml

    defaults:                 # hold for every job unless the job says otherwise
      preset: fast
      minutes: 15             # or iters: 4500
      seeds: [0]
      set: [train.threads=1]  # config overrides, as fit --set takes them
      mesh: {res: 300, color: true}
    jobs:
      - name: mug
        data: scans/mug       # an EventNeRF-layout dataset folder
        gt: scans/mug/gt.ply  # scored with hybridneus eval after meshing
      - name: cup
        recording: rec/cup.aedat4
        convert: [--poses, rec/cup.csv, --calib, rec/calib.json, --clock-offset, auto]
        seeds: [0, 1]

Relative paths are taken from the manifest's folder. A job with several seeds becomes one job
per seed, named ``<name>-s<seed>``. ``mesh: false`` stops after the fit; ``report: false``
leaves out the run's ``report.html`` (``hybridneus report`` writes it later).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from hybridneus.errors import ConfigError

#: Keys a job may state; every one but ``name``, ``data``, ``recording`` and ``gt`` may also
#: stand in ``defaults``.
JOB_KEYS = ("name", "data", "recording", "convert", "preset", "set", "seeds", "iters",
            "minutes", "device", "mesh", "report", "gt")
DEFAULT_KEYS = tuple(k for k in JOB_KEYS if k not in ("name", "data", "recording", "gt"))
#: Meshing when a manifest does not say: EventNeRF's resolution, coloured.
DEFAULT_MESH = {"res": 300, "color": True}


@dataclass(frozen=True)
class JobSpec:
    """One fit of a batch, with what to do before and after it.

    Attributes:
        id: the job's name in the batch (its folder under the runs folder).
        data: an EventNeRF-layout dataset folder, or None when ``recording`` is converted.
        recording: a recording to convert first (``hybridneus convert``), or None.
        convert: the convert command's options (poses, calibration, ...).
        preset: the fit's preset.
        overrides: config overrides (``fit --set``).
        seed: the fit's seed.
        iters: training steps, or None (the preset's, or ``minutes``).
        minutes: a wall-clock budget instead of ``iters``, or None.
        device: ``auto``, ``cpu``, ``cuda`` or ``cuda:N``.
        mesh: ``{"res": int, "color": bool}``, or None for no mesh.
        gt: a ground-truth mesh to score against, or None.
        report: write the run's ``report.html`` last (``hybridneus report``).
    """

    id: str
    data: str | None
    recording: str | None = None
    convert: tuple[str, ...] = ()
    preset: str = "fast"
    overrides: tuple[str, ...] = ()
    seed: int = 0
    iters: int | None = None
    minutes: float | None = None
    device: str = "auto"
    mesh: dict | None = field(default_factory=lambda: dict(DEFAULT_MESH))
    gt: str | None = None
    report: bool = True

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def load_manifest(path: str | Path) -> list[JobSpec]:
    """The jobs of a manifest file, seeds expanded, in the file's order.

    Raises:
        ConfigError: the file is missing or not YAML, or states an unknown key, a job without
            a dataset, two jobs of one name, or a value of the wrong kind (naming the file and
            the job).
    """
    import yaml

    path = Path(path)
    try:
        doc = yaml.safe_load(path.read_text())
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such manifest") from None
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        raise ConfigError(f"{path}: not a readable YAML manifest "
                          f"({str(exc).splitlines()[0]})") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("jobs"), list) or not doc["jobs"]:
        raise ConfigError(f"{path}: expected a mapping with a non-empty 'jobs' list")
    unknown = set(doc) - {"defaults", "jobs"}
    if unknown:
        raise ConfigError(f"{path}: unknown top-level key {sorted(unknown)[0]!r} (expected "
                          "defaults, jobs)")
    defaults = doc.get("defaults") or {}
    if not isinstance(defaults, dict):
        raise ConfigError(f"{path}: defaults: expected a mapping")
    bad = set(defaults) - set(DEFAULT_KEYS)
    if bad:
        raise ConfigError(f"{path}: defaults: unknown key {sorted(bad)[0]!r} (expected "
                          f"{', '.join(DEFAULT_KEYS)})")
    jobs: list[JobSpec] = []
    for k, entry in enumerate(doc["jobs"]):
        if not isinstance(entry, dict):
            raise ConfigError(f"{path}: jobs[{k}]: expected a mapping")
        jobs += _expand(path, k, {**defaults, **entry})
    seen: set[str] = set()
    for job in jobs:
        if job.id in seen:
            raise ConfigError(f"{path}: two jobs are named {job.id!r}")
        seen.add(job.id)
    return jobs


def _expand(path: Path, k: int, entry: dict) -> list[JobSpec]:
    where = f"{path}: job {entry.get('name', k)!r}"
    bad = set(entry) - set(JOB_KEYS)
    if bad:
        raise ConfigError(f"{where}: unknown key {sorted(bad)[0]!r} (expected "
                          f"{', '.join(JOB_KEYS)})")
    name = entry.get("name")
    if not isinstance(name, str) or not name or "/" in name or name.startswith("."):
        raise ConfigError(f"{where}: 'name' must be a plain folder name")
    if ("data" in entry) == ("recording" in entry):
        raise ConfigError(f"{where}: give one of 'data' (a dataset folder) or 'recording'")
    if "iters" in entry and "minutes" in entry:
        raise ConfigError(f"{where}: give one of 'iters' and 'minutes'")
    base = path.parent

    def where_is(key: str) -> str | None:
        value = entry.get(key)
        if value is None:
            return None
        if not isinstance(value, str):
            raise ConfigError(f"{where}: '{key}' must be a path")
        return str(base / Path(value).expanduser())

    seeds = entry.get("seeds", [0])
    if isinstance(seeds, int) and not isinstance(seeds, bool):
        seeds = [seeds]
    if not (isinstance(seeds, list) and seeds and all(
            isinstance(s, int) and not isinstance(s, bool) for s in seeds)):
        raise ConfigError(f"{where}: 'seeds' must be a list of integers")
    mesh = entry.get("mesh", True)
    if mesh is True:
        mesh = dict(DEFAULT_MESH)
    elif mesh is False or mesh is None:
        mesh = None
    elif isinstance(mesh, dict) and set(mesh) <= {"res", "color"}:
        mesh = {**DEFAULT_MESH, **mesh}
    else:
        raise ConfigError(f"{where}: 'mesh' must be true, false or {{res: N, color: bool}}")
    report = entry.get("report", True)
    if not isinstance(report, bool):
        raise ConfigError(f"{where}: 'report' must be true or false")
    common = dict(
        report=report, data=where_is("data"), recording=where_is("recording"),
        convert=_strings(where, "convert", entry.get("convert", [])),
        preset=str(entry.get("preset", "fast")),
        overrides=_strings(where, "set", entry.get("set", [])),
        iters=_number(where, "iters", entry.get("iters"), int),
        minutes=_number(where, "minutes", entry.get("minutes"), float),
        device=str(entry.get("device", "auto")), mesh=mesh, gt=where_is("gt"))
    if common["convert"] and common["recording"] is None:
        raise ConfigError(f"{where}: 'convert' options need a 'recording'")
    return [JobSpec(id=name if len(seeds) == 1 else f"{name}-s{s}", seed=s, **common)
            for s in seeds]


def _strings(where: str, key: str, value) -> tuple[str, ...]:
    if not isinstance(value, list) or not all(isinstance(v, str | int | float) for v in value):
        raise ConfigError(f"{where}: '{key}' must be a list of strings")
    return tuple(str(v) for v in value)


def _number(where: str, key: str, value, kind):
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float) or value <= 0:
        raise ConfigError(f"{where}: '{key}' must be a positive number, got {value!r}")
    return kind(value)


__all__ = ["DEFAULT_MESH", "JobSpec", "load_manifest"]
