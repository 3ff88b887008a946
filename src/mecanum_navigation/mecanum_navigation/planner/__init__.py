"""The global planner: A* on the costmap, shortcutting and smoothing."""
