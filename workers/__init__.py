"""Ray orchestration for datagen jobs (sharding, resumable runs). Library code lives in ``datagen``."""
