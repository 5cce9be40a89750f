// placeholder: writeIes
