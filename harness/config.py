"""Experiment configs: a TOML file -> a validated ExperimentConfig (docs/experiments.md).

Everything is checked before any work starts: each field's type and range, each
planner's name and parameters (the planner is constructed once), and every scene file
(loaded once). A bad config raises InputError naming the file and the field.
"""

from __future__ import annotations

import fnmatch
import glob
import hashlib
import json
import math
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

from harness.errors import InputError
from harness.protocol import ENGINES, PAD_STIFFNESS
from harness.scene import LIBRARY, library_names, load_scene, outline_files, resolve
from harness.toml_table import Table, read_toml

#: Protocol fields a config may override, with their ranges (low, high, low end open). The
#: bounds keep a trial finite and the motion physical: a step from 1e-4 s (20 times finer
#: than Bullet's design step; the fidelity studies go 4 times finer) to 0.01 s, phases of
#: at most 10 s, a lift of at most 1 m, a shake of at most 50 Hz, 0.5 m and pi rad.
_PROTOCOL_KEYS = {"time_step": (1e-4, 0.01, False), "lift_height": (0.0, 1.0, True), "lift_time": (0.0, 10.0, True),
                  "hold_time": (0.0, 10.0, False), "shake_time": (0.0, 10.0, False),
                  "shake_frequency": (0.0, 50.0, True), "shake_amplitude": (0.0, 0.5, False),
                  "shake_turn": (0.0, math.pi, False), "table_friction": (0.0, 10.0, False)}
#: Grasp settings (harness.settings) an experiment may override, by the table that holds them.
_SETTING_TABLES = {"evaluation": ("sigma_g", "friction", "friction_spread", "load_factor"),
                   "gripper": ("opening", "jaw_width", "sigma_g", "force", "closing_speed", "plate_height")}


@dataclass(frozen=True)
class PlannerEntry:
    """One planner of an experiment: its label in the tables, registry name, parameters."""

    label: str
    name: str
    params: dict


@dataclass(frozen=True)
class ExperimentConfig:
    """A validated experiment config (see docs/experiments.md)."""

    name: str
    source: str
    seed: int
    scenes: tuple[str, ...]            # scene files, resolved
    realisations: int
    planners: tuple[PlannerEntry, ...]
    analytic_draws: int
    posterior_trials: int
    truth_trials: int
    time_budget_s: float
    settings: dict = field(default_factory=dict)  # overrides of every scene's grasp settings
    physics: dict = field(default_factory=dict)   # overrides of the trial protocol
    batch_size: int = 16
    scene_names: tuple[str, ...] = ()  # each scene file's `name`: the key of its plans and trials

    def __post_init__(self):
        if len(self.scene_names) != len(self.scenes):  # configs stored before names were kept
            object.__setattr__(self, "scene_names", stored_scene_names(asdict(self)))

    def content(self) -> dict:
        """What determines the results of every planner alike: the settings and the scene
        files' text. Not the planners: each planner's rows are its own (its own random
        stream and trial batches, keyed by its label), so a config with a planner more
        or fewer is the same experiment, and resuming it plans and simulates only the
        planners not yet recorded (harness.experiment checks that a recorded label was
        planned with the same planner and parameters)."""
        d = asdict(self)
        for key in ("source", "name", "scene_names", "planners"):
            d.pop(key)
        d["scenes"] = {name: hashlib.sha256(Path(p).read_bytes()).hexdigest()
                       for name, p in zip(self.scene_names, self.scenes, strict=True)}
        # The outline files a scene reads are part of it: an edited outline is another
        # experiment, not a resume. Keyed as the scene file writes them (no machine's
        # absolute paths); only for scenes that read one, so other hashes stay as they were.
        outlines = {name: {written: hashlib.sha256(Path(f).read_bytes()).hexdigest() for written, f in found}
                    for name, p in zip(self.scene_names, self.scenes, strict=True) if (found := outline_files(p))}
        if outlines:
            d["outline_files"] = outlines
        # Recorded whether or not the config sets it: a ledger whose samples' bodies were
        # outlined on the belief's own cells (before body_refinement) is not resumed into
        # rows made with finer ones.
        protocol = self.protocol()
        d["body_refinement"] = protocol.body_refinement
        # Likewise Bullet's pads (rigid before they were compliant); MuJoCo's rows do not
        # depend on them, and its hashes stay as they were.
        if protocol.engine == "pybullet":
            d["pads"] = [protocol.pad_stiffness, protocol.pad_damping]
        return d

    @property
    def hash(self) -> str:
        text = json.dumps(self.content(), sort_keys=True, default=str)
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    def as_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "ExperimentConfig":
        """The inverse of as_dict (the ledger keeps the config as JSON). Configs written
        before the settings were one field (sigma_g, friction, friction_spread and gripper
        side by side) read as their overrides."""
        d = dict(d)
        legacy = {k: d.pop(k) for k in ("sigma_g", "friction", "friction_spread") if k in d}
        settings = {**(d.pop("gripper", None) or {}), **{k: v for k, v in legacy.items() if v is not None},
                    **d.pop("settings", {})}
        return cls(**{**d, "settings": settings, "scenes": tuple(d["scenes"]),
                      "scene_names": tuple(d.get("scene_names", ())),
                      "planners": tuple(PlannerEntry(**p) for p in d["planners"])})

    def protocol(self):
        """The trial protocol: the engine's own (its time step and iterations), then the
        config's overrides."""
        from harness.protocol import Protocol

        physics = dict(self.physics)
        return Protocol.of(physics.pop("engine", "pybullet"), **physics)

    @property
    def engine(self) -> str:
        return self.physics.get("engine", ENGINES[0])

    def with_engine(self, engine: str) -> "ExperimentConfig":
        """The same experiment in another engine, named NAME-ENGINE (``eval --engine``);
        itself when it already runs there."""
        if engine == self.engine:
            return self
        physics = {k: v for k, v in self.physics.items() if k != "engine"}
        if engine != ENGINES[0]:
            physics["engine"] = engine
        return replace(self, name=f"{self.name}-{engine}", physics=physics)

    def cells(self) -> list[tuple[str, str, int]]:
        """(scene file, scene name, realisation) of every cell, in order."""
        return [(path, name, r) for path, name in zip(self.scenes, self.scene_names, strict=True)
                for r in range(self.realisations)]


def stored_scene_names(config: dict) -> tuple[str, ...]:
    """The scene names of a config as the ledger stores it (ExperimentConfig.as_dict).
    Configs stored before the names were kept name each scene by its file's `name` if
    it still loads, else by its file name."""
    names = tuple(config.get("scene_names") or ())
    if len(names) == len(config["scenes"]):
        return names
    return tuple(_file_scene_name(path) for path in config["scenes"])


def _file_scene_name(path: str) -> str:
    try:
        return load_scene(path).name
    except InputError:
        return Path(path).stem


def load_config(path: str | Path) -> ExperimentConfig:
    """Read and validate an experiment config; InputError (file, field, reason) on bad input."""
    path = Path(path)
    if not path.is_file():
        raise InputError(str(path), None, "no such experiment config")
    return parse_config(read_toml(path), source=str(path), base_dir=path.parent, default_name=path.stem)


def parse_config(data: dict, source: str, base_dir: Path, default_name: str = "experiment") -> ExperimentConfig:
    from planners.registry import make_planner

    root = Table(data, "", source)
    name = root.string("name", default_name)
    if not name or any(c in name for c in "/\\") or name.startswith(".") or not name.isprintable():
        raise root.error("name", f"{name!r} cannot name a results folder")
    seed = root.integer("seed", 0, lo=0, hi=2**63 - 1)
    scenes = _scene_files(root, base_dir)
    realisations = root.integer("realisations", 3, lo=1, hi=1000)

    ev = root.table("evaluation", required=False)
    analytic = ev.integer("analytic_draws", 1000, lo=1, hi=1_000_000)
    posterior = ev.integer("posterior_trials", 100, lo=0, hi=100_000)
    truth = ev.integer("truth_trials", 50, lo=0, hi=100_000)
    budget = ev.number("time_budget_s", 60.0, lo=0.0, hi=86_400.0, lo_open=True)
    settings = _setting_overrides({"evaluation": ev, "gripper": root.table("gripper", required=False)})

    phys = root.table("physics", required=False)
    protocol = {key: phys.number(key, None, lo=lo, hi=hi, lo_open=lo_open)
                for key, (lo, hi, lo_open) in _PROTOCOL_KEYS.items() if key in phys.data}
    if "solver_iterations" in phys.data:
        protocol["solver_iterations"] = phys.integer("solver_iterations", None, lo=1, hi=10_000)
    if "body_refinement" in phys.data:
        protocol["body_refinement"] = phys.integer("body_refinement", None, lo=1, hi=8)
    for key in ("cone_friction", "table_hull", "convex_clipping"):
        if key in phys.data:
            protocol[key] = phys.boolean(key)
    engine = phys.string("engine", ENGINES[0], choices=ENGINES)
    if protocol.get("convex_clipping") and engine != "pybullet":
        raise phys.error("convex_clipping", f"Bullet's alone; the engine is '{engine}'")
    for key in ("pad_stiffness", "pad_damping"):
        if key in phys.data:
            protocol[key] = phys.number(key, None, lo=0.0, hi=1e9)
            if engine != "pybullet":
                raise phys.error(key, f"Bullet's alone (MuJoCo's pads are soft by solref); the engine is '{engine}'")
    if "pad_damping" in protocol and protocol["pad_damping"] <= 0.0 < protocol.get("pad_stiffness", PAD_STIFFNESS):
        raise phys.error("pad_damping", "a compliant pad (pad_stiffness > 0) needs pad_damping > 0 N s/m")
    if engine != ENGINES[0]:  # the default engine is left out, so configs written before engines keep their hash
        protocol["engine"] = engine
    batch = phys.integer("batch_size", 16, lo=1, hi=64)
    phys.finish()

    entries = []
    for t in root.tables("planners", min_count=1):
        pname = t.string("name")
        label = t.string("label", pname)
        params_t = t.table("params", required=False)
        params = dict(params_t.data)
        params_t.used.update(params)
        t.finish()
        try:
            make_planner(pname, params, source=source)
        except InputError as exc:
            raise InputError(source, f"{t.where}.{'params.' + exc.field if exc.field else 'name'}",
                             exc.message) from None
        if not label or any(c in label for c in "/\\") or not label.isprintable():
            raise t.error("label", f"{label!r} is not a usable label")
        if label == "all":
            raise t.error("label", "'all' is the tables' name for every planner pooled; give the entry another label")
        if label in {e.label for e in entries}:
            raise t.error("label", f"'{label}' is used twice (give each planner entry its own label)")
        entries.append(PlannerEntry(label, pname, params))
    root.finish()

    names = [load_scene(path).name for path in scenes]  # every scene must load, before any work starts
    for k, scene_name in enumerate(names):
        if scene_name in names[:k]:
            first = scenes[names.index(scene_name)]
            raise root.error("scenes", f"{first} and {scenes[k]} are both named '{scene_name}' "
                                       "(plans and trials are stored by scene name: give each its own)")
    return ExperimentConfig(name, source, seed, tuple(scenes), realisations, tuple(entries), analytic,
                            posterior, truth, budget, settings, protocol, batch, tuple(names))


def _setting_overrides(tables: dict) -> dict:
    """The grasp settings a config overrides, from [evaluation] and [gripper]; a setting
    given in both is an error (which one would win is not obvious)."""
    from harness.settings import BOUNDS

    found: dict = {}
    for table_name, keys in _SETTING_TABLES.items():
        t = tables[table_name]
        for key in keys:
            if key not in t.data:
                continue
            lo, hi, lo_open = BOUNDS[key]
            value = t.number(key, None, lo=lo, hi=hi, lo_open=lo_open)
            if key in found:
                raise t.error(key, f"is also set in [{found[key][0]}]: set each grasp setting once")
            found[key] = (table_name, value)
        t.finish()
    return {key: value for key, (_, value) in found.items()}


def _scene_files(root: Table, base_dir: Path) -> list[str]:
    entries = root.list("scenes")  # required: a config without it must not quietly run the whole library
    if not entries:
        raise root.error("scenes", "needs at least one scene")
    files: list[str] = []
    for k, entry in enumerate(entries):
        if not isinstance(entry, str) or not entry:
            raise root.error(f"scenes[{k}]", f"expected a scene name, glob or path, got {entry!r}")
        looks_like_path = entry.endswith(".toml") or "/" in entry
        if any(c in entry for c in "*?["):
            try:
                if Path(entry).is_absolute():  # Path.glob takes relative patterns only
                    matches = sorted(p for p in glob.glob(entry) if Path(p).is_file())
                elif looks_like_path:
                    matches = sorted(str(p) for p in base_dir.glob(entry) if p.is_file())
                else:
                    matches = [str(LIBRARY / f"{n}.toml") for n in library_names() if fnmatch.fnmatch(n, entry)]
            except ValueError as exc:  # pathlib's word on a malformed pattern ('**' inside a name)
                raise root.error(f"scenes[{k}]", f"'{entry}' is not a usable pattern: {exc}") from None
            if not matches:
                raise root.error(f"scenes[{k}]", f"'{entry}' matches no scene")
        else:
            target = str(base_dir / entry) if looks_like_path and not Path(entry).is_absolute() else entry
            try:
                matches = [str(resolve(target))]
            except InputError as exc:
                raise root.error(f"scenes[{k}]", exc.message) from None
        files.extend(m for m in matches if m not in files)
    return files
