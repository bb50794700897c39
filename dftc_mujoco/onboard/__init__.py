"""The onboard algorithms of the DFTC architecture (paper Fig. 1), pure numpy.

Nothing in this package imports MuJoCo: each block sees only what a robot
would have on board (its own measurement and inputs, its in-neighbours'
messages, its own sensors, and the mission every robot is given).
"""
