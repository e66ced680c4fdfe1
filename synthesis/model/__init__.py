"""The model of a problem: transition systems, objectives, test strategies, errors."""
