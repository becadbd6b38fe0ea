"""railval.app — the Panel web application, services that join db and core, and the CLI."""
