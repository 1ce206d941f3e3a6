"""Where a run stands (:class:`RunState`) and the save that records and restores it (:class:`Checkpoint`, mirrored;
:func:`load_checkpoint` reads one safely).

A save is whole or absent. ``checkpoint.pt`` is its commit point: the run's state, networks and optimisers, and a
record (``save``) of the other files that belong to it, each with its size and SHA-256: the replay buffer and the
best policy under ``save/``, written under names of their own before the commit (``buffer-000012.pt``), and the
length of every logged scalar's CSV file at that instant. ``checkpoint.pt`` is written beside and renamed over the
old one, flushed to the disk; the files of the save before it are removed only after. So a kill at any instant
leaves the previous save or the new one, whole: ``--resume`` checks each file against the record, truncates the
logs to their recorded length (no row is logged twice), and puts ``best_policy.pt`` back to the save's copy. Every
file is plain tensors and containers (``torch.load(weights_only=True)``), with no pickled field and no class named
by the file.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import shutil
from dataclasses import dataclass
from pathlib import Path

import torch

from atrv_warp.policy import Normalize, check_policy_task, policy_payload
from atrv_warp.rl.config import TrainConfig
from atrv_warp.rl.learner import make_learner
from atrv_warp.rl.run import RunSpec, resolve_run
from atrv_warp.storage import FileFormatError, atomic_save, file_sha256, load_weights, sync_folder

__all__ = ["BUFFER_FORMAT", "CHECKPOINT_KEYS", "RESUME_IDENTITY", "Checkpoint", "RunLock", "RunMismatch", "RunState",
           "buffer_state", "load_buffer_state", "load_checkpoint"]

RESUME_IDENTITY = (("env", "robot"), ("env", "task"), ("network", "width"), ("network", "depth"),
                   ("optim", "algo"), ("optim", "loss"), ("run", "seed"))
"""The settings that make a run the run it is: a resume that changes one is another run, and is refused naming it
(``init_from=`` starts a new run from its networks, on purpose)."""


class RunMismatch(ValueError):
    """A resume that would continue a run as another one (one line naming what differs), or a run folder in use."""


class RunLock:
    """One training per run folder: an exclusive lock on its ``training.lock``, taken before anything is written and
    held until :meth:`release` (or the process ends: the system frees a dead process's lock, kill -9 included).

    Raises:
        RunMismatch: Another process holds the folder (its pid named, as it wrote it in the file).
    """

    def __init__(self, run_dir: Path):
        import fcntl

        self.made = [p for p in (run_dir, *run_dir.parents) if not p.exists()]
        """The folders this lock made (none existed): a run that writes nothing leaves none of them behind."""
        run_dir.mkdir(parents=True, exist_ok=True)
        self.path = run_dir / "training.lock"
        self._file = open(self.path, "a+")  # noqa: SIM115 - held open for the run: the lock lives with the descriptor
        try:
            fcntl.flock(self._file, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            self._file.seek(0)
            holder = self._file.read().strip() or "?"
            self._file.close()
            raise RunMismatch(f"{run_dir} is in use by another training (pid {holder}): two runs in one folder would "
                              "mix their saves and logs; wait for it, or train under another name=") from None
        self._file.seek(0)
        self._file.truncate()
        self._file.write(f"{os.getpid()}\n")
        self._file.flush()

    def release(self) -> None:
        """Let the folder go (the file stays; the lock is the descriptor's). A folder this lock made, in which nothing
        but the lock was written (a run refused before its first file), is removed with the folders made for it."""
        if self._file.closed:
            return
        if self.made and [p.name for p in self.path.parent.iterdir()] == [self.path.name]:
            self.path.unlink()
            for folder in self.made:  # the run folder first, then each one made above it, while empty
                if folder.exists() and not any(folder.iterdir()):
                    folder.rmdir()
        self._file.close()


CHECKPOINT_KEYS = ("frames", "updates", "best_success", "elapsed_s", "next_eval", "stats_ready", "rng", "policy")
"""Entries every training checkpoint holds (``loss`` and ``opts`` too once learning has started)."""

BUFFER_FORMAT = "atrv_warp.replay_buffer/1"
"""The saved replay buffer: its rows in storage order (each key a tensor, nested keys joined by dots), its length
and its writer's state."""


@dataclass
class RunState:
    """Where a run stands; saved in every checkpoint and restored by ``--resume``."""

    frames: int = 0
    updates: int = 0
    best_success: float = -1.0
    best_return: float = -math.inf
    """Mean return of the best policy's evaluation: the tie-break between equal success rates."""
    elapsed_s: float = 0.0
    next_eval: int = 0
    stats_ready: bool = False
    """Observation statistics are frozen and the learner exists (after ``init_random_frames``)."""
    tracking_id: str = ""
    """The W&B or MLflow run the scalars go to (``logger=wandb|mlflow``): a resumed run continues it."""
    run_id: str = ""
    """The run's identity, drawn when it starts, kept in every save and in the run folder's ``run.json``: a save is
    resumed only in the folder of the run that wrote it (``""``: a save from before runs had one)."""


def load_checkpoint(path: Path) -> dict:
    """Read a training checkpoint (``weights_only``); a damaged one is a ``FileFormatError`` naming it."""
    ck = load_weights(path, "training checkpoint", CHECKPOINT_KEYS)
    if ck["stats_ready"] and not ({"loss", "opts"} <= ck.keys()):
        raise FileFormatError(f"{path}: not a complete training checkpoint: learner state missing")
    if not isinstance(ck["rng"], torch.Tensor) or ck["rng"].dtype != torch.uint8:
        raise FileFormatError(f"{path}: not a complete training checkpoint: bad random-generator state")
    return ck


def _on_cpu(value):
    """``value`` (state dicts: dicts, lists and tuples of tensors and numbers) with every tensor on the CPU."""
    if isinstance(value, torch.Tensor):
        return value.detach().cpu()
    if isinstance(value, dict):
        return {k: _on_cpu(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return type(value)(_on_cpu(v) for v in value)
    return value


def buffer_state(buffer) -> dict:
    """A replay buffer as plain tensors and numbers (:data:`BUFFER_FORMAT`): what a save writes."""
    from tensordict import TensorDict

    n = len(buffer)
    rows = buffer.storage[:n]
    rows = rows.exclude("index") if isinstance(rows, TensorDict) else rows  # the row's own position, set on extend
    return {"format": BUFFER_FORMAT, "length": n, "writer": dict(buffer.writer.state_dict()),
            "rows": {k: v.detach().cpu().clone() for k, v in rows.flatten_keys(".").items()}}


def load_buffer_state(buffer, state: dict, source: Path) -> None:
    """Fill an empty replay buffer from :func:`buffer_state`'s record: the same rows at the same places, the same
    write cursor.

    Raises:
        FileFormatError: Another format, rows of unequal length, or more rows than the buffer holds (named).
    """
    from tensordict import TensorDict

    rows, n = state.get("rows"), state.get("length")
    if state.get("format") != BUFFER_FORMAT or not isinstance(rows, dict) or not isinstance(n, int):
        raise FileFormatError(f"{source}: not a replay buffer of format {BUFFER_FORMAT!r}")
    if not all(isinstance(v, torch.Tensor) and v.shape[:1] == (n,) for v in rows.values()):
        raise FileFormatError(f"{source}: damaged replay buffer (rows of unequal length)")
    if n > buffer.storage.max_size:
        raise FileFormatError(f"{source}: holds {n:,} transitions, more than this run's buffer_size "
                              f"{buffer.storage.max_size:,}: resume with optim.buffer_size={n} or more")
    if n:
        buffer.extend(TensorDict(rows, [n]).unflatten_keys("."))
    buffer.writer.load_state_dict(state["writer"])


class Checkpoint:
    """A run's save (module docstring): :meth:`save` writes one whole, :meth:`restore` reads it back, mirrored.

    The loop stages a new best policy in :attr:`best` when a validation finds one; the next :meth:`save` writes it
    with the rest and then publishes ``best_policy.pt``.
    """

    def __init__(self, run_dir: Path):
        self.run_dir = run_dir
        self.path = run_dir / "checkpoint.pt"
        """The commit point."""
        self.folder = run_dir / "save"
        """The files a save names beside ``checkpoint.pt``."""
        self.best_path = run_dir / "best_policy.pt"
        self.logs = run_dir / "logs" / "scalars"
        self.generation = 0
        """The saves so far (the current one's number)."""
        self.files: dict[str, dict] = {}
        """The current save's files: ``buffer`` and ``best_policy``, each ``{"path", "bytes", "sha256"}`` (the path
        relative to the run folder)."""
        self.best: dict | None = None
        """A best policy (its payload) not yet saved."""
        self.notes: list[str] = []
        """Lines for the console from :meth:`restore` (what it could not read, and why)."""
        self.identity = run_dir / "run.json"
        """The run folder's identity: the ``run_id`` of the run it holds."""

    # ---------------------------------------------------------------- saving
    def save(self, cfg: TrainConfig, state: RunState, actor, learner, buffer, *, run: RunSpec | None = None) -> None:
        """Write a new save and make it current (``learner``: SAC's :class:`~atrv_warp.rl.learner.Learner`, PPO's
        :class:`~atrv_warp.rl.ppo.PPOLearner`, or ``None`` before learning starts; ``run``: ``cfg`` resolved, whose
        task and robot the save records)."""
        run = run or resolve_run(cfg)
        generation, files = self.generation + 1, dict(self.files)
        self.folder.mkdir(parents=True, exist_ok=True)
        if learner is not None and len(buffer):
            files["buffer"] = self._write(f"buffer-{generation:06d}.pt", buffer_state(buffer))
        if self.best is not None:
            files["best_policy"] = self._write(f"best_policy-{generation:06d}.pt", self.best)
        sync_folder(self.folder)
        payload = {**dataclasses.asdict(state), "rng": torch.get_rng_state(), "config": dataclasses.asdict(cfg),
                   "policy": policy_payload(actor, width=cfg.network.width, depth=cfg.network.depth,
                                          meta={"frames": state.frames, "task": cfg.env.task}, task=run.task,
                                          record=run.record()),
                   "save": {"generation": generation, "files": files, "logs": self._log_lengths()}}
        if learner is not None:
            learned = learner.state_dict()
            # a run trained on a GPU reads back on any machine
            payload.update(learned if cfg.run.device == "cpu" else _on_cpu(learned))
        atomic_save(payload, self.path)  # the commit: from here on, this save is the run's
        self.generation, self.files, self.best = generation, files, None
        self._publish_best()
        self._remove_others()

    def _write(self, name: str, obj) -> dict:
        path = self.folder / name
        atomic_save(obj, path)
        return {"path": str(path.relative_to(self.run_dir)), "bytes": path.stat().st_size, "sha256": file_sha256(path)}

    def _log_lengths(self) -> dict[str, int]:
        """Every logged scalar's CSV file and its length [bytes] now."""
        return {p.name: p.stat().st_size for p in sorted(self.logs.glob("*.csv"))} if self.logs.is_dir() else {}

    def _publish_best(self) -> None:
        """``best_policy.pt`` made equal to the save's (copied beside, then renamed over it)."""
        entry = self.files.get("best_policy")
        if entry is None or (self.best_path.is_file() and self.best_path.stat().st_size == entry["bytes"]
                             and file_sha256(self.best_path) == entry["sha256"]):
            return
        tmp = self.best_path.with_suffix(".pt.tmp")
        shutil.copyfile(self.run_dir / entry["path"], tmp)
        tmp.replace(self.best_path)
        sync_folder(self.run_dir)

    def _remove_others(self) -> None:
        """Files under ``save/`` that the current save does not name (earlier saves', a killed save's)."""
        keep = {self.run_dir / e["path"] for e in self.files.values()}
        for path in self.folder.glob("*"):
            if path not in keep and path.is_file():
                path.unlink()

    def claim(self, run_id: str) -> None:
        """Record ``run_id`` as the folder's run (``run.json``), before its first save."""
        self.run_dir.mkdir(parents=True, exist_ok=True)
        self.identity.write_text(json.dumps({"run_id": run_id}) + "\n")

    def folder_run_id(self) -> str:
        """The ``run_id`` the folder's ``run.json`` holds (``""``: none, or one that does not read)."""
        try:
            value = json.loads(self.identity.read_text()).get("run_id", "")
        except (OSError, ValueError, AttributeError):
            return ""
        return value if isinstance(value, str) else ""

    def start_over(self) -> None:
        """Remove what a run that never completed a save left in its folder: its scalars' CSV files (a new run would
        append to them), ``save/`` and half-written files. Nothing of a completed save is touched.

        Raises:
            FileExistsError: The folder holds a save (``checkpoint.pt``).
        """
        if self.path.exists():
            raise FileExistsError(f"{self.run_dir} already holds a run; use --resume to continue it or another name=")
        for path in [*self.logs.glob("*.csv"), *self.folder.glob("*"), *self.run_dir.glob("*.tmp")]:
            if path.is_file():
                path.unlink()

    # ---------------------------------------------------------------- restoring
    def restore(self, ck: dict, cfg: TrainConfig, actor, normalize: Normalize, buffer, *,
                run: RunSpec | None = None) -> tuple[RunState, object]:
        """Load a checkpoint read by :func:`load_checkpoint` into fresh networks and buffer, check and read the files
        its save names, cut the logs back to the save and put ``best_policy.pt`` back to the save's.

        Raises:
            FileFormatError: A file of the save missing, of another size or checksum, or damaged (named); networks
                that do not match this run's.
        """
        # keys added after a checkpoint was written take their defaults
        state = RunState(**{f.name: ck[f.name] for f in dataclasses.fields(RunState) if f.name in ck})
        learner = None
        run = run or resolve_run(cfg)
        self._check_same_run(ck, cfg, run, state)
        check_policy_task(ck["policy"], run.task, source=self.path)  # a policy that cannot drive the task
        try:
            actor.load_state_dict(ck["policy"]["state_dict"])
            if state.stats_ready:
                learner = make_learner(cfg, actor, normalize)
                learner.load_state_dict(ck)
        except (KeyError, TypeError, ValueError, RuntimeError) as err:
            raise FileFormatError(f"{self.path}: does not match this run's networks (width={cfg.network.width}, "
                                  f"depth={cfg.network.depth}): {_first_line(err)}") from None
        torch.set_rng_state(ck["rng"])
        save = ck.get("save")
        if not isinstance(save, dict):  # written before whole saves: its buffer is a TorchRL folder
            if (self.run_dir / "buffer").is_dir():
                self.notes.append(f"{self.run_dir / 'buffer'}: a replay buffer written before whole saves is not read "
                                  "(such a folder may hold pickled objects); the run refills its buffer")
            return state, learner
        self.generation, self.files = int(save["generation"]), dict(save["files"])
        for name, entry in self.files.items():
            self._verify(name, entry)
        if "buffer" in self.files:
            path = self.run_dir / self.files["buffer"]["path"]
            load_buffer_state(buffer, load_weights(path, "replay buffer", ("format", "rows")), path)
        self._cut_logs(save.get("logs", {}))
        self._publish_best()
        if self.folder.is_dir():
            self._remove_others()
        return state, learner

    def _check_same_run(self, ck: dict, cfg: TrainConfig, run: RunSpec, state: RunState) -> None:
        """Refuse a resume that is another run: a save another run's (its ``run_id`` is not the folder's), a setting
        of :data:`RESUME_IDENTITY` changed, or a robot file that changed since the save (each named). A folder
        without ``run.json`` (from before) takes the save's identity."""
        from atrv_warp.policy import PolicyRobotMismatch, check_policy_robot, policy_record

        folder = self.folder_run_id()
        if state.run_id and folder and state.run_id != folder:
            raise RunMismatch(f"{self.path}: this save belongs to run {state.run_id}, but the folder {self.run_dir} "
                              f"holds run {folder} (run.json): a save is resumed in its own run's folder only")
        saved = ck.get("config") if isinstance(ck.get("config"), dict) else {}
        for group, name in RESUME_IDENTITY:
            before, now = (saved.get(group) or {}).get(name), getattr(getattr(cfg, group), name)
            if before is not None and before != now:
                raise RunMismatch(f"--resume {self.run_dir}: {group}.{name}={now!r}, but the run trained with "
                                  f"{group}.{name}={before!r}: a resume continues its run as it was; start a new run "
                                  f"from its networks on purpose with init_from={self.path} (another name=)")
        try:
            check_policy_robot(policy_record(ck["policy"]), run.robot, source=self.path)
        except PolicyRobotMismatch:
            raise RunMismatch(f"--resume {self.run_dir}: the robot {cfg.env.robot} is not the one the run trained on "
                              "(its robot file or URDF changed since the save: robot.json holds the run's): a resume "
                              f"continues its run as it was; start a new run with init_from={self.path}") from None
        state.run_id = state.run_id or folder

    def _verify(self, name: str, entry: dict) -> None:
        path = self.run_dir / entry["path"]
        if not path.is_file():
            raise FileFormatError(f"{path}: the {name} of the save {self.path} names is missing")
        if path.stat().st_size != entry["bytes"] or file_sha256(path) != entry["sha256"]:
            raise FileFormatError(f"{path}: the {name} differs from the one the save {self.path} recorded (its size "
                                  "or checksum): damaged, or from another save")

    def _cut_logs(self, lengths: dict[str, int]) -> None:
        """Each scalar's CSV file back to its length at the save; those first written after it removed."""
        if not self.logs.is_dir():
            return
        for path in self.logs.glob("*.csv"):
            keep = lengths.get(path.name)
            if keep is None:
                path.unlink()
            elif path.stat().st_size > keep:
                with open(path, "r+b") as f:
                    f.truncate(keep)


def warm_start(path: str | Path, cfg: TrainConfig, actor, normalize: Normalize, *,
               run: RunSpec | None = None) -> object | None:
    """Load the actor (with its observation statistics) and the learner of the checkpoint at ``path`` into a
    new run's networks (``run.init_from``); ``None`` when that run had not started learning. A checkpoint whose
    policy commands or observes another kind than ``cfg.env.task``'s is refused
    (:class:`~atrv_warp.policy.PolicyTaskMismatch`), before anything is loaded."""
    ck = load_checkpoint(Path(path))
    check_policy_task(ck["policy"], (run or resolve_run(cfg)).task, source=path)
    try:
        actor.load_state_dict(ck["policy"]["state_dict"])
        if not ck["stats_ready"]:
            return None
        learner = make_learner(cfg, actor, normalize)
        learner.load_state_dict(ck)
    except (KeyError, TypeError, ValueError, RuntimeError) as err:
        raise FileFormatError(f"{path}: does not match this run's networks (algo={cfg.optim.algo}, width="
                              f"{cfg.network.width}, depth={cfg.network.depth}): {_first_line(err)}") from None
    return learner


def _first_line(err: Exception) -> str:
    return (str(err).strip().splitlines() or [type(err).__name__])[0][:200]
