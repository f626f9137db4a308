"""The application: configuration, the command line, the tick loop and the cell's state."""
