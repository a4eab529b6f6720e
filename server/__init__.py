"""Cell composition: configuration, clock, supervisor, monitoring model and the command line."""
