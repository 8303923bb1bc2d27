"""A recording's views as `monet process` gives them to the detector (no ROS): read one
view's message (a JPEG left encoded until its crop is known), then decode the JPEGs of an
instant at their crops' scale. One implementation for `monet process` and `monet process
--subjects` (commands.process, commands.process_subjects)."""


def view_problem(image, camera):
    """Why a view read by io.images.view_for_crop cannot go to the detector (None when it
    can): the rig's size."""
    if image.shape[:2] != (camera.height, camera.width):
        return (f'image is {image.shape[1]}x{image.shape[0]}, the rig says '
                f'{camera.width}x{camera.height}')
    return None


def read_view(message, camera, reader, reduced_decode=True):
    """(view, problem) of one view's BagMessage: a JPEG CompressedImage stays its BagMessage
    when reduced_decode (only its header is read: crop_views decodes it at the crop's scale),
    anything else is (array, layout) of io.images.view_for_crop (the detector node's rule:
    the raw buffer, converted to RGB only after cropping). view None: the view is left out;
    problem: why it is skipped (counted per camera), None for a view that does not decode
    (counted in reader.report, as iter_multiview_frames does)."""
    from monet_ros.io.images import view_for_crop
    from monet_ros.io.jpeg_scale import is_jpeg, jpeg_size

    msg = message.msg
    try:
        if reduced_decode and hasattr(msg, 'format') and is_jpeg(msg.data):
            width, height = jpeg_size(msg.data)
            if (width, height) != (camera.width, camera.height):
                return None, (f'image is {width}x{height}, the rig says '
                              f'{camera.width}x{camera.height}')
            return message, None
        image, layout = view_for_crop(msg)
    except Exception as exc:    # noqa: BLE001 - a bad image costs only its view
        reader.report.skip(message.topic, f'image decode failed: {exc}')
        return None, None
    problem = view_problem(image, camera)
    return (None, problem) if problem is not None else ((image, layout), None)


def read_frame_views(frame, topics, by_name, reader, reduced_decode, figures):
    """(cameras, views) of one synchronized frame (io.iter_multiview_frames' Frame): every
    topic's view read by read_view, in `topics` order; by_name: camera name -> Camera. A
    skipped view is counted in figures['skipped_views'][name] with its first reason in
    figures['skip_reasons'][name]; a view absent from the frame or that does not decode is
    left out (the caller counts missing views)."""
    present, views = [], []
    for name in topics:
        if name not in frame.images:
            continue
        view, problem = read_view(frame.images[name], by_name[name], reader, reduced_decode)
        if problem is not None:
            figures['skipped_views'][name] += 1
            figures['skip_reasons'].setdefault(name, f'{problem} at stamp {frame.stamp_ns}')
        if view is not None:
            present.append(by_name[name])
            views.append(view)
    return present, views


def crop_views(views, cameras, boxes, out_size, reader, threads):
    """[(image, layout, camera, box) or None] to give Detector.predict for views read by
    read_view: an (array, layout) view as it is; the JPEG BagMessages decoded at their
    crop's scale (io.jpeg_scale.decode_views on `threads`, the Detector's view_threads), or
    None (counted in reader.report) when one does not decode."""
    from monet_ros.io.jpeg_scale import decode_views
    from monet_ros.io.reader import BagMessage

    jpegs = [i for i, view in enumerate(views) if isinstance(view, BagMessage)]
    decoded = dict(zip(jpegs, decode_views(
        [(views[i].msg.data, cameras[i], boxes[i]) for i in jpegs], out_size, threads)))
    out = []
    for i, (view, camera, box) in enumerate(zip(views, cameras, boxes)):
        if i not in decoded:
            out.append((*view, camera, box))
        elif isinstance(decoded[i], ValueError):
            reader.report.skip(view.topic, f'image decode failed: {decoded[i]}')
            out.append(None)
        else:
            out.append(decoded[i][:4])
    return out
