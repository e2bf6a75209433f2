"""A simulated MAVLink camera (camera protocol v2): `camera.Camera` is the pure core (modes,
captures, zoom, focus, storage, the distance trigger), `messages` builds what it says,
`jpeg` writes each photo as a real JPEG with EXIF GPS tags, `service` is the component."""
