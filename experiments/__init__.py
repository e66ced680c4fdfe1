"""FlowTest package."""
