"""The backend's core: settings, database and ORM models, API errors, time, auth and their repositories."""
