"""Running the batch: planning jobs, executing them, progress."""
