"""End-to-end tests: documents, installation, reproducibility, examples and benchmark peers."""
