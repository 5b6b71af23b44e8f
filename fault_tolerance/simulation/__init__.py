"""Runs: integrate a resolver along a task path, lock events, the servo model and the run record."""
