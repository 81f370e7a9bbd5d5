"""`python3 -m formation_agent.config`: print the folder that holds the example robot parameter files."""

from formation_agent.config import DIRECTORY

if __name__ == '__main__':
    print(DIRECTORY)
