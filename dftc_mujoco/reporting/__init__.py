"""What a run leaves and says: its result (the records and every field derived from them
after the run, saved or opened again), its outcome as a user judges it, and the lines
printed about it."""
