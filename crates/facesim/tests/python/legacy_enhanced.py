"""Convert a single-frame CT series into one multi-frame Legacy Converted Enhanced CT file.

Usage: legacy_enhanced.py SERIES_DIR OUT_FILE [--syntax UID] [--interleave]

The fixture of crates/facesim/tests/library/dicom_codecs.rs: highdicom, an independent implementation of
the DICOM multi-frame IODs, writes the functional groups (plane position and orientation, pixel
measures, pixel value transformation: shared when every slice agrees, per frame otherwise) from
the single-frame headers. --interleave stores the frames out of spatial order (the even slices,
then the odd ones, without a dimension index), as a reader must not assume frame order.
"""

import argparse
from pathlib import Path

import highdicom
import pydicom
from pydicom.uid import generate_uid


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("series", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--syntax", default=None)
    ap.add_argument("--interleave", action="store_true")
    a = ap.parse_args()
    slices = [pydicom.dcmread(p) for p in sorted(a.series.iterdir()) if p.is_file()]
    if a.interleave:
        slices = slices[0::2] + slices[1::2]
    enhanced = highdicom.legacy.LegacyConvertedEnhancedCTImage(
        legacy_datasets=slices,
        series_instance_uid=generate_uid(),
        series_number=901,
        sop_instance_uid=generate_uid(),
        instance_number=1,
        transfer_syntax_uid=a.syntax,
        include_dimension_index=not a.interleave,
    )
    enhanced.save_as(a.out, enforce_file_format=True)


if __name__ == "__main__":
    main()
