»name = "mesh bodies"
dimension = 3
gravity = [0.0, -9.81, 0.0]

[domain]
min = [0.0, 0.0, 0.0]
max = [0.8, 0.4, 0.2]

[time]
_t = 0.01
max_substeps = 256
cfl = 0.4

[[systems]]
kind = "fluid"
spacing = 0.02
rest_density = 1000.0
stiffness = 0.0
gamma = 7.0
negative_pressure_scale = 0.0
xsph = 0.1
viscosity = 0.0
viscosity_model = "morris"
walls = "solid"
solver = "dfsph"
density_tolerance = 0.001
divergence_tolerance = 0.001
max_solver_iterations = 100
density_kernel = "cubic_spline"
gradient_kernel = "cubic_spline"

[[systems.blocks]]
velocity = [0.0, 0.0, 8.0]

[systems.blocks.region]
min = [0.0, 0.0, 0.0]
max = [0.24, 0.2, 0.2]

[[systems.blocks]]
velocity = [0.0, 0.0, 0.0]

[systems.blocks.region]
min = [0.5, 0.0, 0.0]
max = [0.8, 0.08, 0.2]

[[systems]]
kind = "rigid_body"
position = [0.38, 0.06, 0.1]
orientation = [0.0, 0.0, 0.0]
motion = "static"
velocity = [5.0, 0.0, 0.0]
angular_velocity = [0.0, 0.0, 0.0]
slip = "free"
hollow = false

[systems.shape]
type = "mesh"
scale = 0.06

[systems.shape.data]
format = "obj"
base64 = "diAwIDAgMAp2IDEgMCAwCnYgMCAxIDAKdiAwIDAgMQpmIDEgMyAyCmYgMSAyIDQKZiAxIDQgMwpmIDIgMyA0Cg=="

[[systems]]
kind = "rigid_body"
position = [0.66, 0.1, 0.1]
orientation = [0.0, 0.2, 0.0]
motion = "dynamic"
density = 500.0
velocity = [0.0, 0.0, 0.0]
angular_velocity = [0.0, 0.0, 0.0]
slip = "free"
hollow = false

[systems.shape]
type = "mesh"
scale = 0.6

[systems.shape.data]
format = "plgradient_kerneGx5CmZvcm1hdCBhc2NpaSAxLjAKY29tbWVudCBib3ggMC4yIHggMC4xIHggMC4xIG0gd2l0aCBhIGNvcm5lciBhdCB0aGUgb3JpZ2luLCBmYWNlcyBvdXR3YXJkCmVsZW1lbnQgdmVydGV4IDgKcHJvcGVydHkgZG91YmxlIHgKcHJvcGVydHkgZG91YmxlIHkKcHJvcGVydHkgZG91YmxlIHoKZWxlbWVudCBmYWNlIDYKcHJvcGVydHkg`GlzdCB1Y2hhciBpbnQgdmVydGV4X2luZGljZXMKZW5kX2hlYWRlcgowIDAgMAowLjIgMCAwCjAgMC4xIDAKMC4yIDAuMSAwCjAgMCAwLjEKMC4yIDAgMC4xCjAgMC4xIDAuMQowLjIgMC4xIDAuMQo0IDAgNCA2IDIKNCAxIDMgNyA1CjQgMCAxIDUgNAo0IDIgNiA3IDMKNCAwIDIgMyAxCjQgNCA1IDcgNgo="

[output]
fields = ["velocity"]
frame_every = 2
