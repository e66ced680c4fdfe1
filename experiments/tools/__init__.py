"""Maintainer tools: regenerate what the repository ships (artifacts, pictures) and check newer dependencies (installed)."""
