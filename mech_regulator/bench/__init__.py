"""Benchmarks of the solvers: what accuracy each achieves on reference scenes and what it costs
(`mech-regulator bench accuracy`)."""
