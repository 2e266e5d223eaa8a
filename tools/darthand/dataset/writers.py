"""Dataset layouts other than the native one (dataset/freihand.py, dataset/webdataset.py)."""

from __future__ import annotations


def _freihand(dataset, out, **options):
    from darthand.dataset.freihand import write_freihand

    return write_freihand(dataset, out, **options)


def _webdataset(dataset, out, **_):
    from darthand.dataset.webdataset import write_webdataset

    return write_webdataset(dataset, out)


FORMATS = {"freihand": _freihand, "webdataset": _webdataset}
