"""conveyor-demo: a pick-and-place station on a Cool Muscle (see README.md)."""
