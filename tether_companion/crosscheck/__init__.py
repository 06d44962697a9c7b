"""Second opinions on our physics from code we did not write (optional extras)."""
