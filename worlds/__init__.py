"""The robot world (thesis ch. 2.5): grid maps, unicycle robot, range sensors,
dynamic obstacles and gymnasium environments. No transport imports.

Importing ``worlds`` registers ``navlearn/Navigation-v0`` and ``navlearn/GridWorld-v0``
with gymnasium (the modules load only when an env is made).
"""

from gymnasium.envs.registration import register, registry

if "navlearn/Navigation-v0" not in registry:
    register(id="navlearn/Navigation-v0", entry_point="worlds.env:NavigationEnv")
if "navlearn/GridWorld-v0" not in registry:
    register(id="navlearn/GridWorld-v0", entry_point="worlds.gridworld:GridWorldEnv")
