"""Run by ParaView's own Python (``pvpython pvpython_probe.py OUT.json FILE...``), not by pytest.

Opens each file with the reader ParaView uses for it (.vtu: XMLUnstructuredGridReader,
.pvtu: XMLPartitionedUnstructuredGridReader, .pvd: PVDReader, .xdmf: Xdmf3ReaderS and the XDMF 2 reader XDMFReader), and writes to
OUT.json, per file and reader, the time steps and every leaf data set: its block name,
point and cell counts, points, and each array's name, association (point, cell or field
data), number of components, VTK type and values. Prints a short account on stdout.
"""

import json
import sys

from paraview import servermanager, simple


def arrays(data, which):
    out = {}
    field = {"point": data.GetPointData, "cell": data.GetCellData, "field": data.GetFieldData}[which]()
    for i in range(field.GetNumberOfArrays()):
        array = field.GetAbstractArray(i)
        n, c = array.GetNumberOfTuples(), array.GetNumberOfComponents()
        out[array.GetName()] = {
            "components": c,
            "type": array.GetDataTypeAsString(),
            "values": ([array.GetComponent(t, k) for t in range(n) for k in range(c)] if array.IsA("vtkDataArray")
                       else [array.GetVariantValue(v).ToString() for v in range(n * c)]),
        }
    return out


def leaves(data, name=""):
    if data.IsA("vtkMultiBlockDataSet"):
        found = []
        for b in range(data.GetNumberOfBlocks()):
            meta = data.GetMetaData(b)
            label = meta.Get(data.NAME()) if meta is not None and meta.Has(data.NAME()) else str(b)
            block = data.GetBlock(b)
            if block is not None:
                found += leaves(block, label)
        return found
    if data.IsA("vtkPartitionedDataSet") or data.IsA("vtkPartitionedDataSetCollection"):
        found = []
        for b in range(data.GetNumberOfPartitionedDataSets() if data.IsA("vtkPartitionedDataSetCollection")
                       else data.GetNumberOfPartitions()):
            block = (data.GetPartitionedDataSet(b) if data.IsA("vtkPartitionedDataSetCollection")
                     else data.GetPartition(b))
            if block is not None:
                found += leaves(block, f"{name}/{b}")
        return found
    n = data.GetNumberOfPoints()
    return [{
        "name": name,
        "class": data.GetClassName(),
        "points": n,
        "cells": data.GetNumberOfCells(),
        "cell_types": sorted({data.GetCellType(i) for i in range(data.GetNumberOfCells())}),
        "coordinates": [data.GetPoint(i) for i in range(n)],
        "point_data": arrays(data, "point"),
        "cell_data": arrays(data, "cell"),
        "field_data": arrays(data, "field"),
    }]


def probe(path):
    if path.endswith(".vtu"):
        readers = {"XMLUnstructuredGridReader": lambda: simple.XMLUnstructuredGridReader(FileName=[path])}
    elif path.endswith(".pvtu"):
        readers = {"XMLPartitionedUnstructuredGridReader":
                   lambda: simple.XMLPartitionedUnstructuredGridReader(FileName=[path])}
    elif path.endswith(".pvd"):
        readers = {"PVDReader": lambda: simple.PVDReader(FileName=path)}
    else:
        readers = {"Xdmf3ReaderS": lambda: simple.Xdmf3ReaderS(FileName=[path]),
                   "XDMFReader": lambda: simple.XDMFReader(FileNames=[path])}
    result = {}
    for name, make in readers.items():
        reader = make()
        times = list(getattr(reader, "TimestepValues", None) or [])
        steps = {}
        for time in times or [None]:
            if time is None:
                reader.UpdatePipeline()
            else:
                reader.UpdatePipeline(time)
            data = servermanager.Fetch(reader)
            steps["none" if time is None else repr(float(time))] = leaves(data)
        result[name] = {"times": times, "steps": steps,
                        "point_arrays": list(reader.PointData.keys()), "cell_arrays": list(reader.CellData.keys())}
        simple.Delete(reader)
    return result


def main():
    out, paths = sys.argv[1], sys.argv[2:]
    report = {path: probe(path) for path in paths}
    with open(out, "w") as handle:
        json.dump(report, handle)
    for path, readers in report.items():
        for reader, found in readers.items():
            print(f"{path} [{reader}] times {found['times']}")
            for step, blocks in found["steps"].items():
                for block in blocks:
                    print(f"  t={step} block {block['name']!r}: {block['class']}, {block['points']} points, "
                          f"{block['cells']} cells, cell types {block['cell_types']}")
                    for kind in ("point_data", "cell_data", "field_data"):
                        for array, info in block[kind].items():
                            v = info["values"]
                            shown = f"range [{min(v):.6g}, {max(v):.6g}]" if v and not isinstance(v[0], str) else v
                            print(f"    {kind[:-5]:5} {array:20} {info['components']} x {info['type']:14} {shown}")


main()
