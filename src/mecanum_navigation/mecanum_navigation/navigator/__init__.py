"""The navigator: goals, route, replanning and recovery behaviours, and its node."""
