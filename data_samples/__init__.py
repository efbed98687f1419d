"""The shipped sample field (installed as ``rimcl.samples``); see README.md here."""
