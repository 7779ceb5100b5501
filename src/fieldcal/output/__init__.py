"""Where results go: export formats, terminal summaries, the HTML report."""
