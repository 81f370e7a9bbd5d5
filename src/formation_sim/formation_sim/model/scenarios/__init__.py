"""Built-in scenarios (YAML), loaded by name through `formation_sim.model.scenario.load_scenario`."""
