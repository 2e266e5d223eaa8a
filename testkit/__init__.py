"""Tools the tests and benchmarks share (a local Ray cluster, the studio's browser harness): they live beside the
package, not in it, so `pip install darthand` does not install them."""
