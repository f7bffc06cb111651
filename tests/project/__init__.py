"""Repository-wide checks: lint, types, layers, docs and their site, gallery, install, tools/."""
