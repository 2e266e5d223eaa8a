"""Rendering a dataset on a Ray cluster (`render-dataset --ray [ADDRESS]`): its chunks rendered by actors spread
over the cluster's nodes.

run.py plans the shards, digests the jobs, keeps the resume records and hands chunks to a runner
(dataset/runner.Runner); this one renders them on the cluster with local.render_chunk, so frame i is the same job,
the same digest and the same bytes whatever the cluster.

    connect.py    connecting the driver to a cluster (addresses, ray.init) and the code digest every node shares
    shipping.py   which input files a node reads where, and those it gets through Ray's object store
    runner.py     RayRunner, on the driver: the actors, the dispatch of chunks, lost nodes, results
    node.py       NodeWorker, the actor on a node: opens the sources, renders chunks, returns frames if it must

Ray is optional (pip install 'darthand[cluster]') and slow to import: no module here imports it at load time.
"""
