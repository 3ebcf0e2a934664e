"""Headless batch runner: CLI, jobs, backends, comparison, summary."""
