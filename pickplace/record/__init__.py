"""A run recorded to Rerun: the recording with its blueprint, and the live viewer connection."""
