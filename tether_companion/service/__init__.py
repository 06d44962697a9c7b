"""The asyncio companion service: ingest, estimate, publish, record, health, systemd."""
