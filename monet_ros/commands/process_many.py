"""`monet process REC... --jobs N`: several recordings, N worker processes.

Each recording is processed by monet_ros.commands.process.process_recording (the same
function as a single run) in its own worker process and written to OUT/<recording name>/
(names made unique with _2, _3, ...), atomically as a single run. Workers are started with
the 'spawn' context: torch's thread pools, CUDA and DDS threads do not survive fork().
With several CUDA devices the jobs are spread over them round-robin (one device per job);
CPU threads are split (default --threads per job = cores // jobs). A failed recording is
reported (one line naming it) and the others go on; each recording's summary (the lines a
run of it alone prints: process.recording_lines) is printed after its name as it ends; the
command ends with a summary table
(recording, its output folder, frames, frames/s, mean reprojection error, status) and exits
2 if any failed.
"""
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
import multiprocessing
from pathlib import Path
import signal
import sys

from monet_ros.config import ConfigError
from monet_ros.cores import threads_each, usable_cores


@dataclass(frozen=True)
class Job:
    """One recording of a multi-recording run: where it is read and written, on which torch
    device (None = auto) and with how many CPU threads (0 = the backend default)."""
    bag: str
    out: str
    device: str = None
    threads: int = 0


def recording_name(bag):
    """The output folder name of a recording: its folder's name, or the file's stem for a
    .mcap / .db3 file."""
    path = Path(bag)
    return path.stem if path.suffix in ('.mcap', '.db3') else path.name


def output_folders(bags, out):
    """OUT/<recording name> per recording, duplicates made unique with _2, _3, ... in the
    order given (two recordings called `session` -> session, session_2)."""
    seen, folders = set(), []
    for bag in bags:
        base = recording_name(bag) or 'recording'
        name, k = base, 1
        while name in seen:
            k += 1
            name = f'{base}_{k}'
        seen.add(name)
        folders.append(str(Path(out) / name))
    return folders


def plan_jobs(bags, out, jobs, device=None, threads=0, cuda_devices=0, cores=1):
    """The Job of each recording. device None (auto) with cuda_devices > 1: cuda:i
    round-robin over the devices; an explicit device is used by every job. threads 0: each
    job gets max(1, cores // min(jobs, len(bags))) threads (the cores split between the
    workers running at once), else `threads` per job."""
    running = max(1, min(jobs, len(bags)))
    per_job = threads or threads_each(running, cores)
    devices = [None] * len(bags)
    if device is None and cuda_devices > 1:
        devices = [f'cuda:{i % cuda_devices}' for i in range(len(bags))]
    elif device is not None:
        devices = [device] * len(bags)
    return [Job(str(bag), folder, dev, per_job)
            for bag, folder, dev in zip(bags, output_folders(bags, out), devices)]


def _stop(signum, frame):
    raise KeyboardInterrupt


def _worker_signals():
    """Workers leave Ctrl-C to the parent, which stops them with SIGTERM: raised as
    KeyboardInterrupt, so process_recording removes its unfinished output folder."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _stop)


def process_job(job, options, work, lines=None):
    """Worker body: process one recording with `work` (process.process_recording, passed
    in so that this module does not import the command that imports it; pickled by name);
    returns a dict (bag, out, frames, seconds, mean_error, error: None or the one-line
    reason; lines: lines(figures, out), the recording's summary as a run of it alone
    prints it: process.recording_lines). Never raises for a bad recording."""
    from monet_ros.cli import bad_input_errors, error_line
    from monet_ros.commands.common import check_threads

    result = dict(bag=job.bag, out=job.out, frames=0, seconds=0.0, mean_error=float('nan'),
                  error=None)
    try:
        check_threads('monet process', job.threads)
        figures = work(job.bag, out=job.out, device=job.device,
                                    threads=job.threads, progress=False, **options)
        result.update(frames=figures['frames'], seconds=figures['seconds'],
                      mean_error=figures['mean_error'],
                      skipped={name: (count, figures['skip_reasons'][name])
                               for name, count in figures['skipped_views'].items()})
        if lines is not None:
            result['lines'] = lines(figures, job.out)
        report = figures['report']
        if report is not None and not report.ok:
            result['read_report'] = report.summary()
    except bad_input_errors() as error:
        result['error'] = error_line(error, 'monet process')
    except Exception as error:  # noqa: BLE001 - one recording's bug must not stop the rest
        result['error'] = f'internal error: {type(error).__name__}: {error_line(error)}'
    return result


def summary_table(results):
    """The closing table, one row per recording in the order given (a list of lines): the
    recording, the output folder that holds its results ('-' when it failed), frames,
    frames/s, mean reprojection error and status."""
    rows = [('recording', 'output', 'frames', 'frames/s', 'mean reproj. error (px)',
             'status')]
    for r in results:
        fps = r['frames'] / r['seconds'] if r['seconds'] else 0.0
        error = r['mean_error']
        rows.append((r['bag'], r['out'] if r['error'] is None else '-', str(r['frames']),
                     f'{fps:.1f}', '-' if error != error else f'{error:.2f}',
                     'ok' if r['error'] is None else 'FAILED'))
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    return ['  '.join(cell.ljust(w) for cell, w in zip(row, widths)).rstrip() for row in rows]


def run_many(args, options, work, lines=None):
    """Process args.bag (several recordings) with args.jobs workers. work:
    process.process_recording; options: its keyword arguments shared by every recording
    (model, rig, config, ...); lines: process.recording_lines, the summary of a recording
    (stdout, after its name, as each recording ends: what a run of it alone prints).
    Returns the exit code: 0, or 2 if any recording failed. --out (the parent of one
    folder per recording) is made; removed again when the run is stopped (Ctrl-C /
    SIGTERM) or fails before a folder was kept in it."""
    if args.jobs < 1 or args.jobs > 256:
        raise ConfigError('monet process', 'jobs', f'must be in 1..256, got {args.jobs}')
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise ConfigError('monet process', 'out', f'{out}: exists and is not a folder (with '
                          'several recordings --out is the parent of one folder each)')
    cuda_devices = 0
    if args.device in (None, '', 'auto'):
        import torch
        cuda_devices = torch.cuda.device_count() if torch.cuda.is_available() else 0
    device = None if args.device in (None, '', 'auto') else args.device
    jobs = plan_jobs(args.bag, out, args.jobs, device, args.threads, cuda_devices,
                     usable_cores())
    from monet_ros.commands.common import made_output_dir
    with made_output_dir(out):         # removed again when stopped before anything was kept
        return _run_jobs(args, options, work, jobs, out, lines)


def _run_jobs(args, options, work, jobs, out, lines=None):
    """run_many's workers: the jobs run, the summary printed; the exit code."""
    from tqdm import tqdm

    results = {}
    context = multiprocessing.get_context('spawn')
    pool = ProcessPoolExecutor(max_workers=min(args.jobs, len(jobs)), mp_context=context,
                               initializer=_worker_signals)
    try:
        futures = {pool.submit(process_job, job, options, work, lines): job for job in jobs}
        done = tqdm(as_completed(futures), total=len(futures), desc='monet process',
                    unit='recording', disable=args.quiet, file=sys.stderr)
        for future in done:
            job = futures[future]
            try:
                result = future.result()
            except Exception as error:  # noqa: BLE001 - a worker died (killed, out of memory)
                result = dict(bag=job.bag, out=job.out, frames=0, seconds=0.0,
                              mean_error=float('nan'),
                              error=f'worker stopped: {type(error).__name__}: {error}')
            results[job.bag, job.out] = result
            if result['error'] is not None:
                print(f'monet process: failed {job.bag}: {result["error"]}', file=sys.stderr,
                      flush=True)
                continue
            for line in result.get('lines', ()):
                print(f'monet process: {job.bag}: {line}', flush=True)
            for name, (count, reason) in sorted(result['skipped'].items()):
                print(f'monet process: {job.bag}: skipped {count} views of {name}: {reason}',
                      file=sys.stderr)
            if 'read_report' in result:
                print(f'monet process: reading {job.bag}: {result["read_report"]}',
                      file=sys.stderr)
    except KeyboardInterrupt:
        # Stop the running workers (SIGTERM: each removes its unfinished output) and wait
        # for them; ProcessPoolExecutor has no public call for this.
        workers = list((getattr(pool, '_processes', None) or {}).values())
        pool.shutdown(wait=False, cancel_futures=True)
        for process in workers:
            process.terminate()
        for process in workers:
            process.join(timeout=60)
        raise
    pool.shutdown(wait=True)
    ordered = [results[job.bag, job.out] for job in jobs]
    for line in summary_table(ordered):
        print(f'monet process: {line}')
    failed = sum(r['error'] is not None for r in ordered)
    print(f'monet process: {len(ordered) - failed} of {len(ordered)} recordings processed '
          f'-> {out}' + (f'; {failed} failed' if failed else ''))
    return 2 if failed else 0
