"""Versioned Arrow schemas for datagen's Parquet shards."""
