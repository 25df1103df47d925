"""Marker trajectories from motion-capture files: C3D (`mocap_c3d`) and OptiTrack Motive / Vicon Nexus CSV exports
(`mocap_csv`); ROS 2 recordings with mocap4r2_msgs/msg/Markers are read by `mocap_samples`.

Every reader returns `MarkerTrajectories`: frame times [ns] on the source's own clock (a file: time since its first
frame, frame number / rate, exact) and positions in metres (NaN where a marker was not measured: a blank cell, NaN,
or a C3D point whose residual is negative). Labels are kept as the file writes them (`Subject:Marker`,
`Asset:Marker`, `Unlabeled 1036`); `mocap_labels` matches them to the robot config. Units come from the file
(C3D `POINT:UNITS`, the CSV header or units row), never assumed: a file without them is refused.

`read_mocap_file` is the one entry point: whatever a damaged or unexpected file provokes in a reader or a library
becomes a `WolfcalError` naming the file.
"""

from __future__ import annotations

from pathlib import Path

from wolfcal.errors import WolfcalError
from wolfcal.io.mocap_trajectories import MarkerTrajectories, NoMarkers


def read_mocap_file(path: Path) -> MarkerTrajectories:
    """A C3D file or a Motive / Vicon Nexus CSV export, by its extension and first line."""
    from wolfcal.io.mocap_c3d import read_c3d
    from wolfcal.io.mocap_csv import read_csv_export

    path = Path(path)
    if not path.is_file():
        raise WolfcalError(f"{path}: motion-capture file not found; check the path")
    suffix = path.suffix.lower()
    if suffix not in (".c3d", ".csv"):
        raise WolfcalError(
            f"{path}: unknown motion-capture file type; give a .c3d file or a Motive / Vicon Nexus .csv export"
        )
    try:
        traj = read_c3d(path) if suffix == ".c3d" else read_csv_export(path)
    except WolfcalError:
        raise
    except MemoryError:
        raise WolfcalError(f"{path}: the file is too large for this computer's memory") from None
    except Exception as exc:  # anything else a damaged file provokes in a reader or a library
        kind = "C3D" if suffix == ".c3d" else "CSV export"
        raise WolfcalError(
            f"{path}: not a readable {kind} ({type(exc).__name__}: {exc}); check that the file is "
            "complete and export it again"
        ) from None
    if not traj.labels:
        raise NoMarkers(f"{path}: the file holds no marker trajectories")
    if len(traj.times_ns) == 0:
        raise WolfcalError(f"{path}: the file holds no frames")
    return traj
