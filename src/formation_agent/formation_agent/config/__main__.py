"""`python3 -m formation_agent.config`: print the folder that holds the example robot parameter files."""

from formation_agent.config import DIRECTORY

print(DIRECTORY)
