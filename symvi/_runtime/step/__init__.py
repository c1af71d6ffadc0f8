"""The step map: one step's Newton, the integration loop and its batches (numpy only)."""
