"""What a run shows: summary.md, report.html, JUnit, and a run entry in words (results.py); an outputs
folder is read back through batch/run_folder.py."""
