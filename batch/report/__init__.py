"""What a run shows: summary.md, report.html, previews, and reading an outputs folder back."""
