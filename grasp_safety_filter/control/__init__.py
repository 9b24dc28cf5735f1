"""Control: nominal controller, constraint families, QP, safety filter, hold policy."""
