"""Many trials: the trial record, the process and Ray backends, statistics, the report and the
sweep's recording.
"""
