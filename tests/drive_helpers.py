"""What the drive's end-to-end test and bench/ros2_drive.py share."""

FAST = ("--max-linear", "1.0", "--linear-accel", "4", "--max-angular", "3", "--angular-accel", "12",
        "--settle-gain", "5", "--rate", "50")  # fmt: skip
"""the drive's limits here: a quick robot, so that an episode takes seconds"""
