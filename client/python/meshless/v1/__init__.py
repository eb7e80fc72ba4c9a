"""Generated gRPC and protobuf modules of package ``meshless.v1``."""
