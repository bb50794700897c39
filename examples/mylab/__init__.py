"""A user's own onboard blocks, outside the dftc_mujoco package (an example lab module).

Select them in a scenario (``[onboard] controller = "mylab.control:Lyapunov"``)
or on the command line (``--set onboard.thresholds=mylab.fdi:Scaled``); they
are imported where the run executes: from sys.path, the scenario's folder or a
campaign spec's folder.
"""
