"""One axis controller: parameters, references, TD + algorithm + limits + bumpless switching."""
