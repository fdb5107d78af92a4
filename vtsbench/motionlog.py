"""Old path of `vtsbench.recordings.motionlog` (motion logs), kept for existing imports."""

from .recordings.motionlog import COLUMNS, TIME_SLACK_S, MotionLog, read_motion_log

__all__ = ["COLUMNS", "TIME_SLACK_S", "MotionLog", "read_motion_log"]
