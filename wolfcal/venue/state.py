"""The session folder: what a venue session has done so far, so that an interrupted one resumes.

`session.json` (written atomically after every sample) holds the robot config's content hash, the plan's key, the
poses taken per phase (by name) and the robot time spent so far [s]. Each run of a phase writes its samples to a
capture part of its own (`<phase>-<n>.mcap`, crash-safe: `io.writer`); a part that a killed run left unfinished
(`.partial`) is rescued with every complete sample (`io.recover`) when the session resumes. Nothing a session
has written is ever overwritten.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

from wolfcal.atomic import write_text_atomic
from wolfcal.errors import WolfcalError
from wolfcal.io.recover import recover_capture

STATE_FILE = "session.json"
# feet views, floor views for the fit, held-out floor views, field views for the fit, held-out field views
PHASES = ("feet", "floor", "check", "field", "field_check")


@dataclass
class SessionState:
    robot: str  # the robot config's path
    robot_sha256: str  # of the robot config and URDF contents
    plan_key: str
    done: dict[str, list[str]] = field(default_factory=lambda: {p: [] for p in PHASES})  # pose names taken
    robot_time_s: float = 0.0  # time the robot spent moving and holding poses, over every run [s]
    runs: int = 0  # how many times the session was started (1 + resumes)
    field: bool = False  # field views instead of floor views (`--field`)

    def save(self, folder: Path) -> None:
        write_text_atomic(folder / STATE_FILE, json.dumps(asdict(self), indent=2) + "\n")


def robot_digest(config_path: Path, urdf: Path) -> str:
    digest = hashlib.sha256()
    for path in (config_path, urdf):
        digest.update(Path(path).read_bytes())
    return digest.hexdigest()


def new_session(folder: Path, state: SessionState) -> None:
    """Start a session in `folder`; refuses a folder that holds one already (resume it instead)."""
    if (folder / STATE_FILE).exists():
        raise WolfcalError(f"--out {folder}: holds a venue session already; continue it with --resume {folder}, "
                           "or choose another folder")  # fmt: skip
    if folder.exists() and not folder.is_dir():
        raise WolfcalError(f"--out {folder}: is a file; give a folder for the session")
    if folder.is_dir() and any(folder.iterdir()):
        raise WolfcalError(f"--out {folder}: the folder holds other files; give a new or empty folder")
    folder.mkdir(parents=True, exist_ok=True)
    state.save(folder)


def load_session(folder: Path, robot_sha256: str) -> tuple[SessionState, list[str]]:
    """The state of an interrupted session, its unfinished parts rescued; and notes on what was rescued. Refuses
    a folder without a session, or one started with another robot config."""
    path = folder / STATE_FILE
    if not path.is_file():
        raise WolfcalError(f"--resume {folder}: no venue session there ({STATE_FILE} missing); start one with "
                           f"--out {folder}")  # fmt: skip
    try:
        state = SessionState(**json.loads(path.read_text()))
        state.done = {p: list(state.done.get(p, [])) for p in PHASES}  # a session of a wolfcal with fewer phases
    except (ValueError, TypeError, AttributeError) as exc:
        raise WolfcalError(f"{path}: not a venue session's state ({exc}); start a new session elsewhere") from None
    if state.robot_sha256 != robot_sha256:
        raise WolfcalError(f"--resume {folder}: the session was started with another robot config or URDF "
                           f"({state.robot}); resume it with that config, or start a new session")  # fmt: skip
    notes = []
    for partial in sorted(folder.glob("*.mcap.partial")):
        target = partial.with_name(partial.name.removesuffix(".partial"))
        count = recover_capture(partial, target) if not target.exists() else 0
        partial.unlink()
        notes.append(f"rescued {count} sample(s) of an unfinished part into {target.name}")
    return state, notes


def parts(folder: Path, phase: str) -> list[Path]:
    """The finished capture parts of a phase, in the order they were taken."""
    found = [p for p in folder.glob(f"{phase}-*.mcap") if p.name.removeprefix(f"{phase}-").removesuffix(".mcap")
             .isdigit()]  # fmt: skip
    return sorted(found, key=lambda p: int(p.name.removeprefix(f"{phase}-").removesuffix(".mcap")))


def next_part(folder: Path, phase: str) -> Path:
    """The file name of a phase's next capture part (none of its parts, finished or not, is reused)."""
    numbers = [int(p.name.split("-", 1)[1].split(".", 1)[0]) for p in folder.glob(f"{phase}-*.mcap*")
               if p.name.split("-", 1)[1].split(".", 1)[0].isdigit()]  # fmt: skip
    return folder / f"{phase}-{max(numbers, default=0) + 1}.mcap"
