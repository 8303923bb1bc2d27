"""`monet label`: a local web page to label keypoints of a multiview recording, with every
other view filled in by geometry (no ROS).

- session.LabelSession: the recording (cameras, instants, images), the skeleton and the
  labels table being edited (monet_ros.labels: one labels model, atomic autosave);
- assist: triangulation of an instant's clicks (the project's robust triangulation),
  ghosts (projections), per-view reprojection errors and flags, epipolar polylines;
- suggest: instants worth labelling (k-means over the detector's 3D output or over image
  thumbnails);
- server: the Flask app (JSON API + the static page in static/, no CDN).
"""
