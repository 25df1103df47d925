"""OpenCV's and FFmpeg's own log lines off for the command line; `wolfcal.cli` imports this before OpenCV loads.

Lines such as `[ WARN:0@0.02] global cap_v4l.cpp:914 open VIDEOIO(V4L2:/dev/video7): can't open camera by index`
or `moov atom not found` speak of OpenCV's internals; every failure they describe is reported by wolfcal itself,
naming the file or device and what to do. Both libraries read these variables when they first log, so they must be
set before OpenCV is imported. A user's own setting is kept (set OPENCV_LOG_LEVEL=INFO to see OpenCV's lines).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENCV_LOG_LEVEL", "SILENT")  # OpenCV's logger: [ WARN ], [ERROR], [ INFO ] lines
os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")  # FFmpeg inside OpenCV's video reader: AV_LOG_QUIET
