"""Registration: strikes of a log placed in the target body frame (or the inertial frame) with the
recorded poses only; the log's truth group is never read."""
