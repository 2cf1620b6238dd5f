"""Robot descriptions in and out: YAML and URDF files read into the model, and a model written back as YAML."""
