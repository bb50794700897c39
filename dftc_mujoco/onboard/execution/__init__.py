"""How the team's onboard period executes the blocks, never what they compute: the N
stacks batched on a robot axis, the compiled period and its plain-Python reference, the
state records handed to compiled code, the pass shared between threads, the log row, and
the check that a set of blocks uses only what each robot may know."""
