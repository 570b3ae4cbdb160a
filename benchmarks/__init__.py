"""Speed checks, run on demand as scripts (README.md); a package only so that ``lint-imports`` sees them."""
