"""Files the harness reads and writes: OpenEXR and PNG images (atomic writes), the results.json schema."""
