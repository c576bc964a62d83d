"""The ``contactfem`` command (``python -m contactfem`` too): the process's BLAS threads set
before anything numerical loads (:mod:`contactfem.threads`), then its command line."""

from contactfem.threads import one_blas_thread


def main() -> None:
    one_blas_thread()
    from contactfem.cli import run

    run()


if __name__ == "__main__":
    main()
