"""hybrids."""
