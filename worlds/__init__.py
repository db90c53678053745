"""The robot world (thesis ch. 2.5): grid maps, unicycle robot, range sensors,
dynamic obstacles and gymnasium environments. No transport imports."""
