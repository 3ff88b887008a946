"""Online SLAM: scan matching, pose graph, occupancy grid mapping (slam_toolbox's job)."""
