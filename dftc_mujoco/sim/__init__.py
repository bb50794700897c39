"""The MuJoCo side: scene composition, robot adapters, actuator faults, the plant.

No control law lives here: these modules turn commands into physics and
physics into measurements.
"""
