"""What a synthesized test is stored as: summary JSON, versioned artifact, cache keys."""
