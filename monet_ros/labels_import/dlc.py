"""DeepLabCut and Lightning Pose labels: CollectedData_<scorer>.csv / .h5 (labelled
frames) and per-video prediction tables (<video>DLC_<model>.csv / .h5, also anipose's
pose-2d files).

Layout (DeepLabCut's published format, a pandas DataFrame):
- columns: a MultiIndex (scorer, bodyparts, coords) or, for multi-animal projects,
  (scorer, individuals, bodyparts, coords); coords are x, y (labels) or x, y, likelihood
  (predictions). In the CSV these are the first 3 (4) rows, the first cell of each naming
  the level ('scorer', 'individuals', 'bodyparts', 'coords').
- index: the image path 'labeled-data/<video>/img0042.png' (one column), or since
  DeepLabCut 2.2 the three parts ('labeled-data', '<video>', 'img0042.png') in three
  columns; for predictions the frame number.
- the H5 holds the same DataFrame (pandas.to_hdf, key 'df_with_missing').
Frame index = the last number in the image name (img0042.png -> 42); camera = the
recording camera whose name the video folder contains (Lightning Pose multiview:
labeled-data/<session>_<view>/...), else the one in the file name
(CollectedData_<view>.csv). Empty / NaN x or y cells are unlabelled keypoints; an empty
/ NaN likelihood beside a point is no score (the point is kept, as from a table without
likelihoods). A prediction table's length is its rows (last frame number + 1), whatever
its last detection. With several individuals each individual is a subject (labels_import:
ids by name, in order of first appearance over the files) and the keypoint is the
bodypart; `monet triangulate` names it '<individual>/<bodypart>'. The unique bodyparts
(individual 'single') are no animal: plain names, subject 0.
"""
import csv
import math
from pathlib import Path
import re

import numpy as np

from monet_ros.labels import LabelError, LabelRow
from monet_ros.labels_import import ImportResult, camera_for, join_notes, subject_note

LEVELS = ('scorer', 'individuals', 'bodyparts', 'coords')
UNIQUE = 'single'      # multi-animal DeepLabCut's individual of the unique bodyparts
_NUMBER = re.compile(r'(\d+)(?!.*\d)')


def frame_of_image(name):
    """Frame index of an image name: the last number of its file name (img0042.png -> 42);
    None when it has none."""
    match = _NUMBER.search(Path(str(name)).stem)
    return int(match.group(1)) if match else None


def _files(paths, suffixes):
    out = []
    for p in paths:
        if p.is_dir():
            out += sorted(f for f in p.rglob('*') if f.suffix.lower() in suffixes
                          and (f.name.startswith('CollectedData') or 'DLC' in f.name))
        else:
            out.append(p)
    if not out:
        raise LabelError(f'{", ".join(map(str, paths))}: no DeepLabCut table (CollectedData*'
                         f'{"/".join(suffixes)}) found')
    return out


def table_rows(source, columns, index, values, cameras=(), camera=None, min_score=0.0,
               camera_map=None, where_of=None, line_of=None, ids=None):
    """LabelRows of one DeepLabCut-layout table.

    columns: list of tuples whose last two levels are (bodypart, coord) and, with 3 levels
    after the scorer, the individual before them; index: per row an image path / parts
    tuple / frame number; values (N, K) float. Returns (rows, keypoints, dropped, frames)
    where keypoints are '<individual>/<bodypart>' with several individuals, dropped counts
    points below min_score (a NaN likelihood is no score: kept) and frames is the table's
    frame count (largest frame number + 1) when the index is frame numbers (predictions),
    else None. With several individuals a row's keypoint is the bodypart, its instance the
    individual and its subject the individual's id in `ids` ({name: id}, filled in order of
    first appearance). The unique bodyparts of a multi-animal project (individual 'single':
    the arena's landmarks, no animal's) keep their plain name and subject 0. A point
    without a position (empty / NaN / inf x or y) is a row with u = v = NaN
    (labels_import's missing points)."""
    ids = {} if ids is None else ids
    levels = [tuple(c) for c in columns]
    groups = {}
    for k, col in enumerate(levels):
        if len(col) < 3:
            raise LabelError(f'{source}: column {col} has no (scorer, bodyparts, coords) '
                             'levels')
        name = col[-2] if len(col) == 3 or col[-3] == UNIQUE else f'{col[-3]}/{col[-2]}'
        coords = groups.setdefault(name, {})
        if str(col[-1]) in coords:      # the later column would replace it without a word
            raise LabelError(f'{source}: field {name}/{col[-1]}: given twice (columns '
                             f'{coords[str(col[-1])] + 1} and {k + 1} of the data)')
        coords[str(col[-1])] = k
    individuals = {c[-3] for c in levels if len(c) == 4 and c[-3] != UNIQUE}
    if len(individuals) == 1:
        groups = {k.split('/', 1)[1]: v for k, v in groups.items()}
    several = len(individuals) > 1
    who = {}                        # group name -> (subject id, instance, bodypart)
    for name in groups:
        if several and '/' in name:
            instance, part = name.split('/', 1)
            who[name] = (ids.setdefault(instance, len(ids)), instance, part)
        else:
            who[name] = (0, '', name)
    for name, coords in groups.items():
        if 'x' not in coords or 'y' not in coords:
            raise LabelError(f'{source}: field coords: bodypart {name!r} lacks x or y '
                             f'(has {", ".join(coords)})')
    rows, dropped = [], 0
    for r, key in enumerate(index):
        where = where_of(r) if where_of else f'row {r + 1}'
        line = line_of(r) if line_of else r + 1
        if isinstance(key, (int, np.integer)):
            frame, cam = int(key), camera_for(Path(source).stem, cameras, camera, camera_map)
        else:
            parts = ([str(p) for p in key] if isinstance(key, tuple)
                     else str(key).replace('\\', '/').split('/'))
            frame = frame_of_image(parts[-1])
            if frame is None:
                name = '/'.join(parts)
                raise LabelError(f'{source}:{where or line}: field image: {name!r} has no '
                                 'frame number in its name (expected e.g. img0042.png)')
            video = parts[-2] if len(parts) > 1 else Path(source).stem
            cam = camera_for(video, cameras, camera, camera_map)
            if cam == video and cam not in cameras:
                cam = camera_for(Path(source).stem, cameras, camera, camera_map)
                if cam not in cameras:
                    cam = video
        for name, coords in groups.items():
            u, v = values[r, coords['x']], values[r, coords['y']]
            score = float(values[r, coords['likelihood']]) if 'likelihood' in coords else None
            if not (math.isfinite(u) and math.isfinite(v)):
                u = v = score = math.nan    # a row without a position (labels_import)
            if score is not None and math.isnan(score):
                score = None                    # an empty likelihood cell: no score
            if score is not None and not score >= min_score:
                dropped += 1
                continue
            subject, instance, part = who[name]
            rows.append(LabelRow(str(source), line, None, frame, cam, part, float(u),
                                 float(v), where, score, subject, instance))
    numbered = len(index) and all(isinstance(k, (int, np.integer)) for k in index)
    frames = int(max(index)) + 1 if numbered else None
    return rows, tuple(groups), dropped, frames


def read_dlc_csv(path, **kwargs):
    """(rows, keypoints, dropped, frames) of a DeepLabCut / Lightning Pose CSV table
    (table_rows)."""
    try:
        with open(path, newline='', encoding='utf-8-sig') as handle:
            lines = list(csv.reader(handle))
    except (OSError, UnicodeDecodeError, csv.Error) as error:
        raise LabelError(f'{path}: cannot read as a DeepLabCut CSV ({error})') from None
    header = []
    while len(header) < len(lines) and lines[len(header)] and \
            lines[len(header)][0].strip() in LEVELS:
        header.append(lines[len(header)])
    names = [h[0].strip() for h in header]
    if 'bodyparts' not in names or 'coords' not in names or names[0] != 'scorer':
        raise LabelError(f'{path}:1: expected header rows scorer, bodyparts, coords (first '
                         f'cells), found {names or [lines[0][0] if lines else "nothing"]}')
    coords_row = header[-1]
    n_index = 1
    while n_index < len(coords_row) and not coords_row[n_index].strip():
        n_index += 1
    width = len(coords_row)
    columns = list(zip(*[h[n_index:width] for h in header]))
    index, values, lines_of = [], [], []
    for number, row in enumerate(lines[len(header):], start=len(header) + 1):
        if not row or all(not c.strip() for c in row):
            continue
        if len(row) != width:
            raise LabelError(f'{path}:{number}: expected {width} fields, got {len(row)}')
        key = row[0] if n_index == 1 else tuple(row[:n_index])
        if n_index == 1 and key.strip().lstrip('-').isdigit():
            key = int(key)
        index.append(key)
        cells = []
        for col, text in zip(columns, row[n_index:]):
            text = text.strip()
            try:
                cells.append(float(text) if text else math.nan)
            except ValueError:
                raise LabelError(f'{path}:{number}: field {"/".join(col[1:])}: {text!r} is '
                                 'not a number') from None
        values.append(cells)
        lines_of.append(number)
    values = np.array(values, float).reshape(len(index), len(columns))
    return table_rows(path, columns, index, values, line_of=lambda r: lines_of[r],
                      where_of=lambda r: '', **kwargs)


def read_dlc_h5(path, **kwargs):
    """(rows, keypoints, dropped, frames) of a DeepLabCut H5 table (pandas / PyTables;
    table_rows)."""
    import pandas as pd
    try:
        frame = pd.read_hdf(path)
    except Exception as error:    # noqa: BLE001 - PyTables / pandas raise many kinds
        text = str(error).strip().splitlines()[-1] if str(error).strip() else type(error).__name__
        raise LabelError(f'{path}: cannot read as a DeepLabCut H5 table ({text})') from None
    columns = list(frame.columns)
    if not columns or not isinstance(columns[0], tuple):
        raise LabelError(f'{path}: columns are not a (scorer, bodyparts, coords) MultiIndex')
    index = [k if isinstance(k, tuple) else (int(k) if isinstance(k, (int, np.integer))
                                             else str(k)) for k in frame.index]
    values = frame.to_numpy(dtype=float, na_value=np.nan)
    return table_rows(path, columns, index, values,
                      where_of=lambda r: f'row {r + 1} ({index[r]})', **kwargs)


def read_dlc_file(path, **kwargs):
    suffix = Path(path).suffix.lower()
    if suffix in ('.h5', '.hdf5'):
        return read_dlc_h5(path, **kwargs)
    if suffix == '.csv':
        return read_dlc_csv(path, **kwargs)
    raise LabelError(f'{path}: expected a DeepLabCut .csv or .h5 file')


def import_dlc(paths, cameras=(), camera=None, min_score=0.0, camera_map=None):
    """ImportResult of DeepLabCut / Lightning Pose files or project folders (CollectedData
    tables are preferred over their H5 twin when both are in a folder)."""
    files = _files(paths, ('.csv', '.h5'))
    csvs = {f.with_suffix('') for f in files if f.suffix == '.csv'}
    files = [f for f in files if not (f.suffix == '.h5' and f.with_suffix('') in csvs)]
    return import_dlc_files(files, cameras, camera, min_score, camera_map)


def import_dlc_files(files, cameras=(), camera=None, min_score=0.0, camera_map=None):
    """ImportResult of DeepLabCut-layout tables (CSV or H5), one after the other; points
    below min_score are left out and counted in the note."""
    rows, keypoints, dropped, counts, ids = [], {}, 0, {}, {}
    for f in files:
        r, k, d, n = read_dlc_file(f, cameras=cameras, camera=camera, min_score=min_score,
                                   camera_map=camera_map, ids=ids)
        rows += r
        keypoints.update(dict.fromkeys(k))
        dropped += d
        if n is not None:
            counts[str(f)] = n
    note = join_notes(f'{dropped} points below --min-score {min_score} left out'
                      if dropped else '', subject_note(ids, 'DeepLabCut individuals'))
    plain = tuple(dict.fromkeys(k.split('/', 1)[-1] for k in keypoints)) if ids \
        else tuple(keypoints)
    return ImportResult(rows, plain, note, counts, ids, tuple(keypoints) if ids else ())
