"""Shared helper of the USD tests."""


def expected_points(mesh, model, weights):
    return mesh.vertices + model.synthesize(weights)
