"""The node programs of a run, each started in a child process (`python -m` or its console script).

They read what the parent wrote into the run folder (`formation_sim.runtime.contract` names it) and
import nothing of the parent's `formation_sim.runtime.launch`.
"""
