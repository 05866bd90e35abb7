"""What the protocol machines give whoever runs them: the effects they return, the marks of a tick."""
