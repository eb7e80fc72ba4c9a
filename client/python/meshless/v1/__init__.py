"""The protocol's messages and gRPC stubs of package ``meshless.v1``,
generated from ``proto/meshless/v1/*.proto`` when the package is built
(``setup.py``): ``scene_pb2``, ``frame_pb2``, ``design_pb2``,
``simulation_pb2``, ``snapshot_pb2`` and ``simulation_pb2_grpc``."""
