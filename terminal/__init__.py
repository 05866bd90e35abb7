"""What the commands share at the terminal: one-line usage errors, exit codes, progress bars."""
