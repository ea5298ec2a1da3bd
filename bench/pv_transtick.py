# What the ParaView benchmarks share (imported by their pvbatch scripts):
# transtick's orbit camera and light, on a ParaView render view.
import math


def volume_geometry(reader):
    """The reader's bounds, dims and spacing."""
    info = reader.GetDataInformation()
    bounds = info.GetBounds()
    extent = info.GetExtent()
    dims = [extent[1] - extent[0] + 1, extent[3] - extent[2] + 1, extent[5] - extent[4] + 1]
    spacing = [(bounds[2 * a + 1] - bounds[2 * a]) / max(1, dims[a] - 1) for a in range(3)]
    return bounds, dims, spacing


def place_camera(view, bounds, dims, spacing, az_deg):
    """transtick's orbit camera (core/src/camera.cc): eye at distance
    radius / sin(fov / 2) * 1.05 from the centre, radius half the diagonal of
    dims * spacing, azimuth about +Y, 0 looking along -Z, 30 degree fov."""
    centre = [(bounds[2 * a] + bounds[2 * a + 1]) / 2 for a in range(3)]
    radius = 0.5 * math.sqrt(sum((dims[a] * spacing[a]) ** 2 for a in range(3)))
    distance = radius / math.sin(math.radians(15)) * 1.05
    az = math.radians(az_deg)
    view.CameraFocalPoint = centre
    view.CameraPosition = [centre[0] + math.sin(az) * distance, centre[1],
                           centre[2] + math.cos(az) * distance]
    view.CameraViewUp = [0, 1, 0]
    view.CameraViewAngle = 30
    view.CameraParallelProjection = 0


def black_background(view, size):
    """An image of size x size on black, keeping the camera the script sets:
    pvbatch resets the camera at the first render unless told not to."""
    from paraview import simple
    simple._DisableFirstRenderCameraReset()
    view.ViewSize = [size, size]
    view.OrientationAxesVisibility = 0
    try:
        view.UseColorPaletteForBackground = 0  # 5.10+: else Background is ignored
    except AttributeError:
        pass
    view.Background = [0, 0, 0]
