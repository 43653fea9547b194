"""The facts of the model that the device stages and the float64 reference both use, in
float64 numpy: radiometry (lights, the phase function, the lamp, the effective far, the
integrand's closed forms), light textures, the geometry of lit intervals and shadow
volumes with the shading normals, the relief pre-warp's geometry, and which faces of a
point light's cube map a frame can read (docs/design.md §5).

The rule of the layers: scene ← physics ← {stages, reference}; tests/layout/test_imports.py
holds it. The reference (clrays.reference) is the yardstick the tests trust, so nothing a
frame runs imports it, but for the `exact` method itself.
"""
