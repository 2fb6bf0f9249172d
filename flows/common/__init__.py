"""Infrastructure the stages share: configuration and warehouse paths, errors, instants, the sensor lake, the warehouse database, file locks, write batches, the allocator."""
