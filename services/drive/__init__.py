"""A trained policy on a ROS 2 robot over Zenoh, as rmw_zenoh speaks it (``navlearn drive``), and a
simulated ROS 2 robot behind the same wire (``navlearn ros2-sim``). See docs/ros2.md."""
