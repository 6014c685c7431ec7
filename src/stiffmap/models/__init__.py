"""Mechanism models: stiffness and static error of robots, evaluated over workspaces and fitted."""
