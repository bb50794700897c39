"""The closed loop: a scenario assembled into a plant and a team, checked before it runs,
stepped period by period (sense, decide, command, physics, monitor, log), and its premises
watched against the truth. The only layer where the plant and the onboard stacks meet."""
