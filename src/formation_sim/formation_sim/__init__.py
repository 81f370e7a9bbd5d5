"""Scenarios, validation, the exact in-process engine, the simulator node and run orchestration."""
