"""Atomic writes, CSVs and directory locks: one of each for every script."""

import contextlib
import csv
import errno
import fcntl
import hashlib
import io
import os
import re
import sys
from pathlib import Path


class InputError(Exception):
    """Bad input: reported as one line, exit status 2."""


class RuntimeFailure(Exception):
    """Work that failed while it ran (a killed worker, a failed run): reported as one line, exit status 1."""


# A file operation that fails with one of these failed at run time (exit 1); any other OSError is a
# file or folder that cannot be used as given (no permission, not a directory: bad input, exit 2).
RUN_TIME_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EIO, errno.EFBIG})


def exit_status(error: BaseException) -> int:
    """Every script's rule: 2 for bad input, 1 for a failure at run time, 130 for Ctrl-C."""
    if isinstance(error, KeyboardInterrupt):
        return 130
    if isinstance(error, RuntimeFailure) or (isinstance(error, OSError) and error.errno in RUN_TIME_ERRNOS):
        return 1
    return 2


def os_error_line(e: OSError) -> str:
    """An OSError in one line naming its file: write_atomic's name it in the message, others in `filename`."""
    named = e.filename and not (e.strerror or "").startswith("cannot")
    return f"{e.filename}: {e.strerror}" if named else str(e.strerror or e)


@contextlib.contextmanager
def one_line_errors():
    """A command's failures as one line on stderr, never a traceback, with exit_status's code: bad
    input (InputError, a file or folder that cannot be used), a failure at run time (RuntimeFailure,
    a full disk)."""
    try:
        yield
    except (InputError, RuntimeFailure) as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(exit_status(e))
    except OSError as e:
        print(f"error: {os_error_line(e)}", file=sys.stderr)
        sys.exit(exit_status(e))


def files_under(folder: Path, pattern: str) -> list[Path]:
    """The files below `folder` whose path ends as `pattern` does (Path.match: `checkpoints/step_*.pt`), sorted.
    Links to folders are followed, each folder searched once, so that a folder of symlinks to run directories is
    searched as the run directories are (Path.rglob follows none) and a link cycle ends."""
    found, searched = [], set()
    for root, folders, names in os.walk(folder, followlinks=True):
        if os.path.realpath(root) in searched:
            folders[:] = []
            continue
        searched.add(os.path.realpath(root))
        found += [Path(root) / name for name in names if (Path(root) / name).match(pattern)]
    return sorted(found)


@contextlib.contextmanager
def replacing(path: Path, tmp_suffix: str = ".tmp"):
    """Yields a temporary path beside `path` (its name + `tmp_suffix`: a writer that picks the format by
    the suffix needs its own, e.g. ".tmp.mp4") and moves it onto `path` when the block ends, so that
    `path` holds either its old or its new content, never a part. On failure (a full disk) no temporary
    file is left and the OSError names `path`."""
    path = Path(path)
    tmp = path.with_name(path.name + tmp_suffix)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        yield tmp
        os.replace(tmp, path)
    except OSError as e:
        tmp.unlink(missing_ok=True)
        raise OSError(e.errno, f"cannot write {path}: {e.strerror or e}") from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_atomic(path: Path, data: bytes | str) -> None:
    """Writes `data` to `path` atomically (see `replacing`)."""
    with replacing(path) as tmp, open(tmp, "wb") as f:
        f.write(data.encode() if isinstance(data, str) else data)
        f.flush()
        os.fsync(f.fileno())  # on disk before the rename: a crash leaves the old file, not an empty one


def csv_text(columns: list[str], rows: list[dict]) -> str:
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=columns, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return text.getvalue()


def write_csv_atomic(path: Path, columns: list[str], rows: list[dict]) -> None:
    write_atomic(path, csv_text(columns, rows))


def read_csv_columns(path: Path) -> tuple[list[str] | None, list[dict]]:
    """(its header, or None for an empty file; its rows) of a CSV. InputError with one line where the
    file is not CSV text (random bytes, a binary file), never a UnicodeDecodeError's traceback."""
    try:
        with open(path, newline="", encoding="utf-8") as f:
            reader = csv.DictReader(f)
            return reader.fieldnames, list(reader)
    except UnicodeDecodeError as e:
        raise InputError(f"{path} is not a CSV: byte {e.start} is not UTF-8 text") from None
    except csv.Error as e:
        raise InputError(f"{path} is not a CSV: {e}") from None


def read_csv(path: Path) -> list[dict]:
    """Every row of a CSV (read_csv_columns)."""
    return read_csv_columns(path)[1]


class LockedError(Exception):
    """A directory another process holds; the message says which process."""


LOCK_FILE = ".lock"


def lock_directory(directory: Path, what: str = "another process"):
    """An exclusive lock on `directory` (flock on its .lock file, holding the holder's pid) for as long
    as the returned file stays open. The kernel drops it when its holder dies, however it dies, so no
    stale lock outlives a killed process. LockedError when another process holds it."""
    handle = open(Path(directory) / LOCK_FILE, "a+")
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        handle.seek(0)
        holder = handle.read().strip() or "unknown"
        handle.close()
        raise LockedError(f"{directory} is in use by {what} (pid {holder})") from None
    handle.truncate(0)
    handle.write(f"{os.getpid()}\n")
    handle.flush()
    return handle


def lock_holder(directory: Path) -> str | None:
    """The pid that holds `directory`'s lock now, or None where no process holds it."""
    path = Path(directory) / LOCK_FILE
    if not path.exists():
        return None
    with open(path) as handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            return handle.read().strip() or "unknown"
    return None


def check_writable(*directories: Path) -> None:
    """Creates each directory and proves it writable (a file created and removed: os.replace needs
    that), before any work whose results would go there. InputError with one line otherwise, or an
    OSError where the disk is full (exit_status)."""
    for directory in map(Path, directories):
        try:
            directory.mkdir(parents=True, exist_ok=True)
            probe = directory / f".probe.{os.getpid()}"
            probe.write_bytes(b"")
            probe.unlink()
        except OSError as e:
            if e.errno in RUN_TIME_ERRNOS:  # a full disk is no fault of the input
                raise OSError(e.errno, f"cannot write to {directory}: {e.strerror or e}") from None
            raise InputError(f"cannot write to {directory}: {e.strerror or e}") from None


# --- a folder's manifest: which of its files a command wrote, so that a rerun removes the stale ones ---

MANIFEST = "outputs.txt"
SHA256 = re.compile(r"[0-9a-f]{64}")


def read_manifest(folder: Path) -> dict[str, str | None]:
    """{name: its sha256 as written} of the outputs the previous run into `folder` listed (paths relative to it);
    none without a manifest. A name listed without a digest (added by hand, or by a version before digests) maps
    to None: it was never shown to be a file the command wrote."""
    path = Path(folder) / MANIFEST
    if not path.is_file():
        return {}
    listed = {}
    for line in path.read_text().splitlines():
        if line and not line.startswith("#"):
            digest, separator, name = line.partition("  ")
            listed.update({name: digest} if separator and SHA256.fullmatch(digest) else {line: None})
    return listed


def write_manifest(folder: Path, written: set[str], writer: str, kept: dict[str, str | None] | None = None) -> None:
    """Lists the files `writer` wrote into `folder` (`written`, names relative to it) with the sha256 of each as it
    is now, in sha256sum's format (`sha256sum -c outputs.txt` checks them), and the `kept` entries of an earlier
    manifest with the digests it recorded (a name it held without one is dropped: no file is vouched for here
    that the command did not write)."""
    entries = {name: digest for name, digest in (kept or {}).items() if digest} | {
        name: sha256_of(Path(folder) / name) for name in written
    }
    header = (f"# the files {writer} wrote into this folder, each with its sha256; a rerun removes those it does not "
              "write again, where they are still the files it wrote\n")  # fmt: skip
    write_atomic(Path(folder) / MANIFEST, header + "".join(f"{entries[name]}  {name}\n" for name in sorted(entries)))


def remove_stale(folder: Path, listed: dict[str, str | None]) -> tuple[list[Path], list[Path]]:
    """Removes the listed files (read_manifest's entries) whose bytes are still those their manifest records, and
    only files inside `folder` (never the manifest itself, a folder or a link's target, never a path that leaves
    `folder`). Returns (those removed, those kept because they differ from their record or have none: a file
    edited since, or named by hand)."""
    removed, kept = [], []
    for name, digest in sorted(listed.items()):
        relative_path = Path(name)
        path = Path(folder) / relative_path
        if relative_path.is_absolute() or ".." in relative_path.parts or name == MANIFEST:
            continue
        if path.is_file() and not path.is_symlink():
            if digest is not None and sha256_of(path) == digest:
                path.unlink()
                removed.append(path)
            else:
                kept.append(path)
    return removed, kept


# --- a folder's record: the CSVs a command wrote, by rows and digest, so that a reader can tell them whole ---

RECORD = "written.csv"


def sha256_of(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def write_record(folder: Path, rows_of: dict[str, int], writer: str) -> None:
    """Records, in `folder`/written.csv, each named file of `folder` with its number of rows and the
    sha256 of its bytes as they are on disk now (written after the files themselves: a crash in between
    leaves a record that no longer matches, which a reader refuses rather than trusts)."""
    rows = [{"file": name, "rows": count, "sha256": sha256_of(Path(folder) / name), "writer": writer}
            for name, count in sorted(rows_of.items())]  # fmt: skip
    write_csv_atomic(Path(folder) / RECORD, ["file", "rows", "sha256", "writer"], rows)


def check_record(path: Path, rows_read: int) -> bool:
    """True where `path`'s folder records it (write_record) and it is what was written; False where no
    record names it (a file of an older sweep, or one copied without its record). InputError with one
    line where it differs from its record: a partial, cut or edited file is never read as whole."""
    path = Path(path)
    record_path = path.parent / RECORD
    if not record_path.is_file():
        return False
    entry = next((r for r in read_csv(record_path) if r.get("file") == path.name), None)
    if entry is None:
        return False
    if sha256_of(path) != entry.get("sha256"):
        raise InputError(f"{path} is not the file its {entry.get('writer') or 'writer'} wrote: it holds {rows_read} "
                         f"rows, {record_path} records {entry.get('rows')} and another digest (a partial, cut or edited "
                         f"file); rerun what wrote it, or remove {record_path} to have the file checked by its contents alone")  # fmt: skip
    return True
