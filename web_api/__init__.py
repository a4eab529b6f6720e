"""The cell's FastAPI application: REST, live events, MTConnect and the dashboard."""
