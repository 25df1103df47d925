"""Printable calibration boards and AprilTag sheets at exact physical size: PDF and PNG.

The PDF is written by hand (a page per sheet: gray images placed at their exact size in points with interpolation
off, vector lines, Helvetica text); the little of the format needed fits in `sheet_pdf`, so no PDF library is
a dependency. Each sheet carries a scale check line: print at 100 % ("actual size", no fit-to-page) and
measure it. The PNG is the same page rasterised at `dpi` with the density in its pHYs chunk; its edges are
exact to one pixel.
"""

from __future__ import annotations

import re
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from wolfcal.atomic import output_set, write_bytes_atomic
from wolfcal.errors import WolfcalError
from wolfcal.outputs import check_outputs
from wolfcal.vision.board import Board, aruco_dictionary
from wolfcal.vision.target_size import check_printed_edge

PAPER = {
    "a4": (0.210, 0.297),
    "a3": (0.297, 0.420),
    "letter": (0.2159, 0.2794),
}  # portrait (width, height) [m]
MARGIN = 0.008  # page margin [m]
TEXT = 0.0028  # text height [m]
FOOTER = 0.013  # room for the scale check line, its label and the title [m]
PT_PER_M = 72 / 0.0254


@dataclass
class Sheet:
    """One page; positions in metres from the page's top-left corner, y down; text at its baseline."""

    width: float
    height: float
    images: list[tuple[np.ndarray, float, float, float, float]] = field(default_factory=list)  # gray, x, y, w, h
    lines: list[tuple[float, float, float, float, float]] = field(default_factory=list)  # x0, y0, x1, y1, width
    texts: list[tuple[float, float, float, str]] = field(default_factory=list)  # x, y, height, text


def _pdf_string(text: str) -> str:
    return (
        "("
        + text.encode("latin-1", "replace")
        .decode("latin-1")
        .replace("\\", "\\\\")
        .replace("(", "\\(")
        .replace(")", "\\)")
        + ")"
    )


def _page_objects(sheet: Sheet, page: int, content_number: int, images: list[int]) -> dict[int, bytes]:
    """The PDF objects of one page: the page, its content stream and its images, at the given numbers."""
    H = sheet.height * PT_PER_M
    ops = []
    for i, (_, x, y, w, h) in enumerate(sheet.images):
        ops.append(
            f"q {w * PT_PER_M:.4f} 0 0 {h * PT_PER_M:.4f} {x * PT_PER_M:.4f} {H - (y + h) * PT_PER_M:.4f} cm "
            f"/Im{i} Do Q"
        )
    for x0, y0, x1, y1, width in sheet.lines:
        ops.append(
            f"{width * PT_PER_M:.4f} w 0 J {x0 * PT_PER_M:.4f} {H - y0 * PT_PER_M:.4f} m "
            f"{x1 * PT_PER_M:.4f} {H - y1 * PT_PER_M:.4f} l S"
        )
    for x, y, size, text in sheet.texts:  # Helvetica cap height ~0.72 em
        ops.append(
            f"BT /F1 {size / 0.72 * PT_PER_M:.3f} Tf {x * PT_PER_M:.4f} {H - y * PT_PER_M:.4f} Td "
            f"{_pdf_string(text)} Tj ET"
        )
    content = zlib.compress("\n".join(ops).encode("latin-1"))
    xobjects = " ".join(f"/Im{i} {number} 0 R" for i, number in enumerate(images))
    objects = {
        page: f"<< /Type /Page /Parent 2 0 R /MediaBox [0 0 {sheet.width * PT_PER_M:.4f} {H:.4f}] "
        f"/Contents {content_number} 0 R /Resources << /Font << /F1 5 0 R >> /XObject << {xobjects} >> >> >>".encode(),
        content_number: f"<< /Length {len(content)} /Filter /FlateDecode >>\nstream\n".encode()
        + content
        + b"\nendstream",
    }
    for number, (image, *_) in zip(images, sheet.images):
        data = zlib.compress(np.ascontiguousarray(image, np.uint8).tobytes())
        objects[number] = (
            f"<< /Type /XObject /Subtype /Image /Width {image.shape[1]} /Height {image.shape[0]} "
            "/ColorSpace /DeviceGray /BitsPerComponent 8 /Interpolate false /Filter /FlateDecode "
            f"/Length {len(data)} >>\n"
            "stream\n".encode()
            + data
            + b"\nendstream"
        )
    return objects


def sheet_pdf(sheets: Sheet | list[Sheet]) -> bytes:
    """A PDF of the sheet(s), one page each, at exact physical size. Objects: 1 catalog, 2 page tree, 3 and 4 the
    first page and its content, 5 the font, then the first page's images and the further pages."""
    sheets = [sheets] if isinstance(sheets, Sheet) else sheets
    objects: dict[int, bytes] = {
        1: b"<< /Type /Catalog /Pages 2 0 R >>",
        5: b"<< /Type /Font /Subtype /Type1 /BaseFont /Helvetica /Encoding /WinAnsiEncoding >>",
    }
    pages, free = [], 6
    for k, sheet in enumerate(sheets):
        page, content = (3, 4) if k == 0 else (free + len(sheet.images), free + len(sheet.images) + 1)
        images = list(range(free, free + len(sheet.images)))
        free += len(sheet.images) + (0 if k == 0 else 2)
        objects.update(_page_objects(sheet, page, content, images))
        pages.append(page)
    kids = " ".join(f"{page} 0 R" for page in pages)
    objects[2] = f"<< /Type /Pages /Kids [{kids}] /Count {len(pages)} >>".encode()
    out = bytearray(b"%PDF-1.4\n%\xe2\xe3\xcf\xd3\n")
    offsets = []
    for number in range(1, len(objects) + 1):
        offsets.append(len(out))
        out += f"{number} 0 obj\n".encode() + objects[number] + b"\nendobj\n"
    xref = len(out)
    out += f"xref\n0 {len(objects) + 1}\n0000000000 65535 f \n".encode()
    out += b"".join(f"{o:010d} 00000 n \n".encode() for o in offsets)
    out += f"trailer\n<< /Size {len(objects) + 1} /Root 1 0 R >>\nstartxref\n{xref}\n%%EOF\n".encode()
    return bytes(out)


def sheet_png(sheet: Sheet, dpi: float) -> bytes:
    """The sheet rasterised at `dpi` as PNG bytes, with the pixel density in a pHYs chunk."""
    ppm = dpi / 0.0254
    page = np.full((int(round(sheet.height * ppm)), int(round(sheet.width * ppm))), 255, np.uint8)
    for image, x, y, w, h in sheet.images:
        c0, r0, c1, r1 = (int(round(a * ppm)) for a in (x, y, x + w, y + h))
        page[r0:r1, c0:c1] = cv2.resize(image, (c1 - c0, r1 - r0), interpolation=cv2.INTER_NEAREST)
    for x0, y0, x1, y1, width in sheet.lines:
        cv2.line(
            page,
            (int(round(x0 * ppm)), int(round(y0 * ppm))),
            (int(round(x1 * ppm)), int(round(y1 * ppm))),
            0,
            max(1, int(round(width * ppm))),
        )
    for x, y, size, text in sheet.texts:
        scale = size * ppm / 22.0  # Hershey simplex: cap height ~22 px at scale 1
        cv2.putText(
            page,
            text,
            (int(round(x * ppm)), int(round(y * ppm))),
            cv2.FONT_HERSHEY_SIMPLEX,
            scale,
            0,
            max(1, int(round(scale * 1.5))),
            cv2.LINE_AA,
        )
    ok, png = cv2.imencode(".png", page)
    assert ok
    data = png.tobytes()
    body = b"pHYs" + struct.pack(">IIB", int(round(ppm)), int(round(ppm)), 1)
    chunk = struct.pack(">I", 9) + body + struct.pack(">I", zlib.crc32(body) & 0xFFFFFFFF)
    end_of_ihdr = 8 + 8 + 13 + 4  # signature, IHDR length + type, IHDR data, CRC
    return data[:end_of_ihdr] + chunk + data[end_of_ihdr:]


def sheet_paths(out: Path, pages: int) -> list[Path]:
    """OUT.pdf, then OUT.png for one page or OUT-p1.png ... OUT-pN.png for several."""
    if pages == 1:
        return [out.with_suffix(".pdf"), out.with_suffix(".png")]
    pngs = [out.with_name(f"{out.stem}-p{k}.png") for k in range(1, pages + 1)]
    return [out.with_suffix(".pdf"), *pngs]


def write_sheet(sheets: Sheet | list[Sheet], out: Path, dpi: float = 300, force: bool = False) -> list[Path]:
    """Write OUT.pdf (every page) and a PNG per page, as one set; existing files only with `force`."""
    sheets = [sheets] if isinstance(sheets, Sheet) else sheets
    paths = sheet_paths(out, len(sheets))
    check_outputs(paths, force)
    with output_set():
        write_bytes_atomic(paths[0], sheet_pdf(sheets))
        for path, sheet in zip(paths[1:], sheets):
            write_bytes_atomic(path, sheet_png(sheet, dpi))
    return paths


def _page(paper: str, content: tuple[float, float]) -> tuple[float, float]:
    """Page size holding `content` (w, h) [m] inside the margins: the paper upright or turned, or fitted."""
    need_w, need_h = content[0] + 2 * MARGIN, content[1] + 2 * MARGIN
    if paper == "fit":
        return need_w, need_h
    if paper not in PAPER:
        raise WolfcalError(f"unknown --paper {paper!r}; use one of {', '.join(PAPER)}, fit")
    w, h = PAPER[paper]
    for page in ((w, h), (h, w)):
        if need_w <= page[0] + 1e-9 and need_h <= page[1] + 1e-9:
            return page
    raise WolfcalError(
        f"{content[0] * 1000:.0f} x {content[1] * 1000:.0f} mm does not fit on {paper} with "
        f"{MARGIN * 1000:.0f} mm margins; use a larger --paper (a3, fit) or smaller squares/tags"
    )


def _add_scale_line(sheet: Sheet, title: str) -> None:
    """Footer: a 100 mm (or 50 mm) line with 10 mm ticks, what it must measure, and the sheet's title."""
    length = 0.1 if sheet.width - 2 * MARGIN >= 0.1 else 0.05
    x0, y = MARGIN, sheet.height - MARGIN - FOOTER + 0.0035
    sheet.lines.append((x0, y, x0 + length, y, 0.0003))
    ticks = int(round(length / 0.01))
    for k in range(ticks + 1):
        tick = 0.003 if k in (0, ticks) else 0.0015
        sheet.lines.append((x0 + k * 0.01, y - tick, x0 + k * 0.01, y, 0.0003))
    note = f"scale check: this line must measure {length * 1000:.0f} mm (print at 100 %, no fit-to-page)"
    sheet.texts.append((x0, y + 0.0045, TEXT, note))
    sheet.texts.append((x0, y + 0.009, TEXT, title))


def board_sheet(board: Board, paper: str = "a4", px_per_square: int = 100) -> Sheet:
    """The board's squares (quiet zone = page margin) with a title and the scale check line."""
    texture = board.texture(px_per_square, margin=0)
    sx, sy = board.squares
    w, h = sx * board.square, sy * board.square
    width, height = _page(paper, (max(w, 0.1), h + FOOTER))
    sheet = Sheet(width, height)
    sheet.images.append((texture, (width - w) / 2, MARGIN + (height - 2 * MARGIN - FOOTER - h) / 2, w, h))
    _add_scale_line(sheet, f"wolfcal {board.describe()} ({sx}x{sy} squares)")
    return sheet


def _tag_pages(paper: str, n: int, pitch_x: float, pitch_y: float) -> tuple[float, float, int, int]:
    """(page width, page height, columns, tags per page) for `n` tags: all on one page if they fit (upright paper
    first, then turned), else as many pages as needed of the orientation that holds the most; 'fit': one page,
    4 columns."""
    if paper == "fit":
        columns = min(n, 4)
        return *_page(paper, (max(columns * pitch_x, 0.1), -(-n // columns) * pitch_y + FOOTER)), columns, n
    if paper not in PAPER:
        raise WolfcalError(f"unknown --paper {paper!r}; use one of {', '.join(PAPER)}, fit")
    w, h = PAPER[paper]
    layouts = []
    for page_w, page_h in ((w, h), (h, w)):
        columns = int((page_w - 2 * MARGIN) / pitch_x + 1e-9)
        rows = int((page_h - 2 * MARGIN - FOOTER) / pitch_y + 1e-9)
        layouts.append((page_w, page_h, columns, columns * rows))
    fitting = [layout for layout in layouts if layout[3] >= n]
    best = fitting[0] if fitting else max(layouts, key=lambda layout: layout[3])
    if best[3] == 0:
        raise WolfcalError(
            f"a tag of this size (with its white border and label) does not fit on {paper} with "
            f"{MARGIN * 1000:.0f} mm margins; use a larger --paper (a3, fit) or a smaller --size"
        )
    return best


def parse_ids(text: str) -> list[int]:
    """'0-7,10,12' -> [0, 1, ..., 7, 10, 12]."""
    ids: list[int] = []
    for part in text.split(","):
        match = re.fullmatch(r"\s*(\d+)\s*(?:-\s*(\d+)\s*)?", part)
        if not match:
            raise WolfcalError(f"--ids {text!r}: give ids and ranges like 0-7,10")
        first, last = int(match[1]), int(match[2] or match[1])
        if last < first:
            raise WolfcalError(f"--ids {text!r}: the range {first}-{last} runs backwards; write {last}-{first}")
        ids += range(first, last + 1)
    return ids


def tag_sheets(family: str, ids: list[int], size: float, paper: str = "a4", cell_px: int = 20) -> list[Sheet]:
    """AprilTags (black square edge `size` [m]) in a grid, labelled with their ids, and the scale line; as many
    pages as the paper needs."""
    check_printed_edge(size, "--size")
    dictionary = aruco_dictionary(family)
    count = len(dictionary.bytesList)
    bad = [i for i in ids if i >= count]
    if bad:
        raise WolfcalError(f"tag ids {bad} do not exist in {family} (ids 0-{count - 1})")
    if not ids:
        raise WolfcalError("no tag ids given (--ids)")
    cells = dictionary.markerSize + 2  # data bits and the black border
    quiet = 2 * size / cells  # white border of two cells around each tag
    pitch_x, pitch_y = size + quiet, size + quiet + TEXT + 0.002
    width, height, columns, per_page = _tag_pages(paper, len(ids), pitch_x, pitch_y)
    chunks = [ids[k : k + per_page] for k in range(0, len(ids), per_page)]
    sheets = []
    for page, chunk in enumerate(chunks, start=1):
        sheet = Sheet(width, height)
        for k, tag_id in enumerate(chunk):
            x = (width - columns * pitch_x) / 2 + (k % columns) * pitch_x + quiet / 2  # grid centred across
            y = MARGIN + (k // columns) * pitch_y + quiet / 2
            image = cv2.aruco.generateImageMarker(dictionary, tag_id, cells * cell_px, borderBits=1)
            sheet.images.append((image, x, y, size, size))
            sheet.texts.append((x, y + size + 0.0015 + TEXT, TEXT, f"id {tag_id}"))
        of = f", page {page} of {len(chunks)}" if len(chunks) > 1 else ""
        _add_scale_line(sheet, f"wolfcal AprilTag {family}, black square {size * 1000:g} mm{of}")
        sheets.append(sheet)
    return sheets
