"""What a run leaves and says: its records (log, events, summary), the fields derived from
them after the run, its outcome as a user judges it, and the lines printed about it."""
