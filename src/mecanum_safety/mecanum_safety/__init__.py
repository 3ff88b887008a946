"""
The command chain that guards every motion of the robot (pure cores and their nodes).

Every velocity command, whatever its source, goes through one chain before it reaches
motor_controller: ``twist_mux`` (one live source at a time, by priority; locks) ->
``collision_monitor`` (obstacles, Nav2's rules) -> ``zone_guard`` (the authorised zone).
:mod:`~mecanum_safety.zone` is the one definition of the authorised zone that
the planner, the guard, robot_controller and the scenario judge all read.
"""
