"""Text commands ("forward 0.5 m", "strafe left 2 s", "rotate left 90 deg") to velocity commands on cmd_vel."""
