"""Built-in scenarios (YAML), loaded by name through `formation_sim.scenario.load_scenario`."""
